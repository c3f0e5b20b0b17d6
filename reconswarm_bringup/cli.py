"""`reconswarm`: the command line. Each command parses its options and calls a module's run(config). The roles'
commands live in their packages (agent/cli.py, simworld/cli.py, monitor/cli.py, also run by `python -m
agent|simworld|monitor`) and are registered here; the conventions every command shares are in reconswarm/cli/.

Exit codes (README.md): 0 success, 1 mission failed (not converged, or a collision), 2 bad input,
3 a process of the run died or could not start. Errors are one line on stderr; `--debug` shows the
traceback.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from reconswarm.cli import help_style, outputs
from reconswarm.cli.console import fail, mission_exit_code, plural, print_json, run_app, set_debug, unconverged_reason
from reconswarm.errors import BadInput, ReconswarmError

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Multi-agent path planning with reconfigurable topology, over Eclipse Zenoh.")
scenario_app = typer.Typer(no_args_is_help=True, help="Generate and validate scenario files.")
app.add_typer(scenario_app, name="scenario")


help_style.install()

DEFAULT_SIM_ROOT = Path("runs") / "sim"


@app.callback()
def _root(debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False) -> None:
    set_debug(debug)

@app.command()
def sim(
    scenario: Annotated[Path, typer.Argument(help="Scenario TOML file.")],
    out: Annotated[Path | None, typer.Option("-o", "--out", metavar="DIR", help="Output directory for run.db "
                   "(default: runs/sim/SCENARIO-PLANNER, with -seedS if --seed is given).")] = None,
    planner: Annotated[str | None, typer.Option(
        "--planner", help="reconfigurable | virtual-leader | orca | hrvo | hl | social-force")] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="Override the scenario's seed.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    record_period: Annotated[float | None, typer.Option(
        "--record-period", metavar="S", help="Record positions every S seconds of simulated time (a multiple of "
        "dt_s) instead of every tick; a recorded tick costs 25 bytes per agent. Minimum gaps, events and the "
        "last tick stay exact.")] = None,
) -> None:
    """Run the mission in one process, vectorized (same math as the distributed deployment)."""
    from reconswarm.record.decimate import BYTES_PER_AGENT_TICK, record_bytes
    from reconswarm.scenario.model import load, warnings
    from reconswarm_bringup import engine

    try:
        s = load(scenario, wire=False)  # (one process: the wire's limits do not apply)
        if planner is not None:
            s = s.with_planner(planner)
        if seed is not None:
            if seed < 0:
                raise BadInput(f"--seed: must be >= 0, got {seed}")
            s = s.with_seed(seed)
        warns = warnings(s)
        for w in warns:
            typer.echo(f"warning: {w}", err=True)
        if out is None:  # one directory per scenario and planner: the quick start's two runs keep both records
            name = f"{scenario.stem}-{s.planner.kind.value}" + ("" if seed is None else f"-seed{seed}")
            out = DEFAULT_SIM_ROOT / name
        outputs.writable_dir("-o", out)
        every = _record_every(record_period, s.meta.dt_s)
        rows = round(s.meta.duration_s / s.meta.dt_s) // every + 2
        if record_bytes(len(s.agents), rows) > 1 << 30:
            typer.echo(f"note: the record may hold {record_bytes(len(s.agents), rows) / 2**30:.3g} GiB of positions "
                       f"({BYTES_PER_AGENT_TICK} bytes per agent per recorded tick, {len(s.agents)} agents, up to "
                       f"{rows:,} recorded ticks); --record-period S records one tick every S seconds", err=True)
        summary = engine.run(engine.SimConfig(s, out, progress=not as_json, record_every=every))
    except (ReconswarmError, OSError) as exc:
        fail(exc)
        return
    if as_json:
        print_json(summary)
    else:
        from rich.console import Console

        from reconswarm.record.summary import render

        Console().print(render(summary))
        db = out / "run.db"
        typer.echo(f"record size: {db.stat().st_size / 2**20:,.1f} MiB ({summary.get('ticks', '?')} ticks recorded, "
                   f"{BYTES_PER_AGENT_TICK} bytes per agent per recorded tick)")
        typer.echo(f"record: {db}")
    for line in unconverged_reason(summary, warns):
        typer.echo(line, err=True)
    raise typer.Exit(mission_exit_code(summary))


def _record_every(period_s: float | None, dt_s: float) -> int:
    """--record-period in ticks: a positive multiple of dt_s (BadInput otherwise)."""
    if period_s is None:
        return 1
    every = round(period_s / dt_s) if period_s > 0 and period_s == period_s and period_s != float("inf") else 0
    if every < 1 or abs(every * dt_s - period_s) > 1e-9 * max(period_s, 1.0):
        raise BadInput(f"--record-period: must be a positive multiple of the scenario's dt_s ({dt_s:g} s), "
                       f"got {period_s:g}")
    return every


@scenario_app.command("generate")
def scenario_generate(
    agents: Annotated[int, typer.Option("--agents", "-n", help="Number of agents.", min=1, max=100_000)],
    obstacles: Annotated[int, typer.Option("--obstacles", "-m", help="Number of obstacles.", min=0, max=1000)] = 3,
    seed: Annotated[int, typer.Option("--seed", "-s", help="Random seed.", min=0)] = 0,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Write to a file instead of stdout.")] = None,
) -> None:
    """Print a valid random scenario (TOML)."""
    from reconswarm.scenario.generate import generate
    from reconswarm.scenario.model import to_toml

    try:
        text = to_toml(generate(agents, obstacles, seed))
    except RuntimeError as exc:
        fail(BadInput(f"--obstacles: {exc}"))
        return
    if out is None:
        sys.stdout.write(text)
        return
    try:
        outputs.writable_file("-o", out)  # (its directory is made if missing)
        out.write_text(text)
    except OSError as exc:
        fail(BadInput(f"-o {out}: cannot write there ({exc.strerror or exc})"))
    except ReconswarmError as exc:
        fail(exc)


@scenario_app.command("check")
def scenario_check(file: Annotated[Path, typer.Argument(help="Scenario TOML file.")],
                   sim_only: Annotated[bool, typer.Option("--sim", help="Check for `reconswarm sim` only: the wire's "
                                                          "limits (launch, distributed runs) do not apply.")] = False
                   ) -> None:
    """Validate a scenario: exit 0, or one line naming the file and field and exit 2."""
    from reconswarm.scenario.model import check

    try:
        s, warns = check(file, wire=not sim_only)
    except ReconswarmError as exc:
        fail(exc)
        return
    for w in warns:
        typer.echo(f"warning: {w}", err=True)
    typer.echo(f"{file}: ok ({plural(len(s.agents), 'agent')}, {plural(len(s.obstacles), 'obstacle')}, "
               f"planner {s.planner.kind.value}{', for sim' if sim_only else ''})")


def _register() -> None:
    from agent.cli import agent_cmd
    from monitor.cli import monitor_app
    from reconswarm_bringup import cli_credentials, cli_launch, cli_nodes, cli_sweep
    from simworld.cli import simworld_cmd

    app.add_typer(monitor_app, name="monitor")
    app.command("agent")(agent_cmd)
    app.command("simworld")(simworld_cmd)
    cli_nodes.register(app)
    cli_launch.register(app)
    cli_sweep.register(app)
    cli_credentials.register(app)


_register()


def main() -> None:
    from reconswarm_bringup.cli_launch import optional_values

    run_app(app, optional_values(sys.argv[1:]))


if __name__ == "__main__":
    main()
