"""`reconswarm`: the command line. Each command parses its options and calls a module's run(config).

Exit codes (INTERFACES.md): 0 success, 1 mission failed (not converged, or a collision), 2 bad input,
3 a process of the run died or could not start. Errors are one line on stderr; `--debug` shows the
traceback.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from reconswarm.errors import BadInput, ProcessFailure, ReconswarmError
from reconswarm_bringup.console import fail, mission_exit_code, print_json, set_debug

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Multi-agent path planning with reconfigurable topology, over Eclipse Zenoh.")
scenario_app = typer.Typer(no_args_is_help=True, help="Generate and validate scenario files.")
app.add_typer(scenario_app, name="scenario")


@app.callback()
def _root(debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False) -> None:
    set_debug(debug)

@app.command()
def sim(
    scenario: Annotated[Path, typer.Argument(help="Scenario TOML file.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Output directory for run.db.")] = Path("runs/sim"),
    planner: Annotated[str | None, typer.Option("--planner", help="reconfigurable | virtual-leader")] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="Override the scenario's seed.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Run the mission in one process, vectorized (same math as the distributed deployment)."""
    from reconswarm.scenario import load, warnings
    from reconswarm_bringup import engine, validate

    try:
        s = load(scenario)
        if planner is not None:
            s = s.with_planner(planner)
        if seed is not None:
            if seed < 0:
                raise BadInput(f"--seed: must be >= 0, got {seed}")
            s = s.with_seed(seed)
        for w in warnings(s):
            typer.echo(f"warning: {w}", err=True)
        validate.writable_dir("-o", out)
        summary = engine.run(engine.SimConfig(s, out, progress=not as_json))
    except (ReconswarmError, OSError) as exc:
        fail(exc)
        return
    if as_json:
        print_json(summary)
    else:
        from rich.console import Console

        from reconswarm.record.summary import render

        Console().print(render(summary))
        typer.echo(f"record: {out / 'run.db'}")
    raise typer.Exit(mission_exit_code(summary))


@app.command()
def sweep(
    scenarios: Annotated[list[Path], typer.Argument(help="Scenario TOML files.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Output directory (results.csv, runs/).")],
    seeds: Annotated[str | None, typer.Option("--seeds", help="A:B, seeds A..B-1 (default: each file's seed).")] = None,
    planner: Annotated[str | None, typer.Option("--planner", help="P[,P...] (default: each file's planner).")] = None,
    jobs: Annotated[int | None, typer.Option("--jobs", "-j", help="Parallel processes (default: cores).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print rows and per-planner stats as JSON.")] = False,
) -> None:
    """Every scenario x seed x planner with the in-process engine, in parallel; results.csv and a table."""
    import os
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool
    from multiprocessing import get_context

    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from reconswarm_bringup import sweep as sw

    try:
        if jobs is not None and jobs < 1:
            raise BadInput(f"--jobs: must be >= 1, got {jobs}")
        seed_range = sw.parse_seeds(seeds)
        kinds = sw.parse_planners(planner)
        for path in scenarios:
            if not path.is_file():
                raise BadInput(f"{path}: no such scenario file")
        job_list = sw.make_jobs(scenarios, seed_range, kinds, out)
        out.mkdir(parents=True, exist_ok=True)
    except (ReconswarmError, OSError) as exc:
        fail(exc)
        return
    workers = max(1, min(jobs or os.cpu_count() or 1, len(job_list)))
    err = Console(stderr=True)
    bar = Progress(TextColumn("sweep"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[last]}"),
                   TimeElapsedColumn(), console=err, transient=True)
    task = bar.add_task("sweep", total=len(job_list), last="")

    def done(job: sw.Job, row: dict[str, Any]) -> None:
        mark = "ok" if row["converged"] and not row["collisions"] else "FAILED"
        bar.update(task, advance=1, last=f"{Path(row['scenario']).name} {row['planner']} seed {row['seed']}: {mark}")

    try:
        # spawn: the workers start clean (no inherited threads or sessions)
        with bar, ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
            rows = sw.run_sweep(job_list, pool, done)
    except BrokenProcessPool as exc:
        fail(ProcessFailure(f"sweep: a worker process died ({exc})"))
        return
    except (ReconswarmError, OSError) as exc:
        fail(exc)
        return
    sw.write_csv(rows, out / "results.csv")
    stats = sw.planner_stats(rows)
    if as_json:
        print_json({"rows": rows, "planners": stats})
    else:
        Console().print(sw.render_stats(stats))
        typer.echo(f"results: {out / 'results.csv'} ({len(rows)} runs, {workers} processes)")


@scenario_app.command("generate")
def scenario_generate(
    agents: Annotated[int, typer.Option("--agents", "-n", help="Number of agents.", min=1, max=100_000)],
    obstacles: Annotated[int, typer.Option("--obstacles", "-m", help="Number of obstacles.", min=0, max=1000)] = 3,
    seed: Annotated[int, typer.Option("--seed", "-s", help="Random seed.", min=0)] = 0,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Write to a file instead of stdout.")] = None,
) -> None:
    """Print a valid random scenario (TOML)."""
    from reconswarm.generate import generate
    from reconswarm.scenario import to_toml

    try:
        text = to_toml(generate(agents, obstacles, seed))
    except RuntimeError as exc:
        fail(BadInput(f"--obstacles: {exc}"))
        return
    if out is None:
        sys.stdout.write(text)
    else:
        out.write_text(text)


@scenario_app.command("check")
def scenario_check(file: Annotated[Path, typer.Argument(help="Scenario TOML file.")]) -> None:
    """Validate a scenario: exit 0, or one line naming the file and field and exit 2."""
    from reconswarm.scenario import check

    try:
        s, warns = check(file)
    except ReconswarmError as exc:
        fail(exc)
        return
    for w in warns:
        typer.echo(f"warning: {w}", err=True)
    typer.echo(f"{file}: ok ({len(s.agents)} agents, {len(s.obstacles)} obstacles, planner {s.planner.kind.value})")


def _register() -> None:
    from reconswarm_bringup.cli_monitor import monitor_app

    app.add_typer(monitor_app, name="monitor")
    from reconswarm_bringup import cli_launch, cli_nodes

    cli_nodes.register(app)
    cli_launch.register(app)


_register()


def main() -> None:
    from reconswarm_bringup.cli_launch import optional_values

    app(args=optional_values(sys.argv[1:]))


if __name__ == "__main__":
    main()
