"""`reconswarm monitor ...`: commands that read a run record (and `record`, the live monitor process)."""

from __future__ import annotations

import csv
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from reconswarm.errors import BadInput, ReconswarmError
from reconswarm_bringup.console import fail, print_json

monitor_app = typer.Typer(no_args_is_help=True, help="Record runs and read run records (run.db).")

DbArg = Annotated[Path, typer.Argument(help="A run record (run.db).")]


def _open(db: Path) -> Any:
    from reconswarm.record.store import RunRecord

    return RunRecord(db)


@monitor_app.command("summary")
def summary_cmd(db: DbArg, as_json: Annotated[bool, typer.Option("--json")] = False) -> None:
    """The run summary (INTERFACES.md fields)."""
    try:
        from reconswarm.record.summary import render, summarize

        rec = _open(db)
        s = summarize(rec)
        rec.close()
    except ReconswarmError as exc:
        fail(exc)
        return
    if as_json:
        print_json(s)
    else:
        from rich.console import Console

        Console().print(render(s))


@monitor_app.command("events")
def events_cmd(db: DbArg, as_json: Annotated[bool, typer.Option("--json")] = False) -> None:
    """Topology (split, merge) and membership (agent_lost, agent_joined) events in time order."""
    try:
        rec = _open(db)
        events = rec.events()
        rec.close()
    except ReconswarmError as exc:
        fail(exc)
        return
    if as_json:
        print_json(events)
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"events in {db}")
    for col in ("t_s", "kind", "before", "after"):
        table.add_column(col)
    for e in events:
        fmt = " | ".join(",".join(map(str, g)) for g in e.get("before", []))
        fmt2 = " | ".join(",".join(map(str, g)) for g in e.get("after", []))
        table.add_row(f"{e['t']:.2f}", e["kind"], fmt, fmt2)
    Console().print(table)


@monitor_app.command("export")
def export_cmd(
    db: DbArg,
    fmt: Annotated[str, typer.Option("--format", help="Output format (csv).")] = "csv",
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Write to a file instead of stdout.")] = None,
) -> None:
    """Trajectories as CSV: t_s,agent,px_m,py_m,theta_rad, one row per agent per tick."""
    try:
        if fmt != "csv":
            raise BadInput(f"--format: unsupported format {fmt!r} (csv)")
        rec = _open(db)
        tk = rec.ticks()
        ids = rec.ids
        rec.close()
    except ReconswarmError as exc:
        fail(exc)
        return
    stream = sys.stdout if out is None else out.open("w", newline="")
    try:
        w = csv.writer(stream, lineterminator="\n")
        w.writerow(["t_s", "agent", "px_m", "py_m", "theta_rad"])
        for row in range(tk.t.size):
            t = f"{tk.t[row]:.6f}"
            for col, aid in enumerate(ids):
                if not np_isfinite(tk.px[row, col]):
                    continue
                w.writerow([t, int(aid), repr(float(tk.px[row, col])), repr(float(tk.py[row, col])),
                            repr(float(tk.theta[row, col]))])
    finally:
        if out is not None:
            stream.close()


def np_isfinite(v: float) -> bool:
    return v == v and v not in (float("inf"), float("-inf"))


@monitor_app.command("plot")
def plot_cmd(
    db: DbArg,
    out: Annotated[Path, typer.Option("-o", "--out", help="PNG file to write.")],
) -> None:
    """Trajectories with obstacles and slots coloured by group, snapshot panels (paper Fig. 4) and the
    tracking error of every agent over time (Fig. 5)."""
    try:
        from monitor.plot import plot_run

        rec = _open(db)
        plot_run(rec, out)
        rec.close()
    except ReconswarmError as exc:
        fail(exc)
        return
    typer.echo(f"wrote {out}")


@monitor_app.command("record")
def record_cmd(
    scenario: Annotated[Path, typer.Option("--scenario", help="Scenario TOML file.")],
    db: Annotated[Path, typer.Option("--db", help="Run record to write (appended to if it exists).")],
    connect: Annotated[list[str] | None, typer.Option("--connect", help="Zenoh endpoint to connect to.")] = None,
    listen: Annotated[list[str] | None, typer.Option("--listen", help="Zenoh endpoint to listen on.")] = None,
    mode: Annotated[str, typer.Option("--mode", help="peer | client | router")] = "client",
    zenoh_config: Annotated[Path | None, typer.Option("--zenoh-config", help="Zenoh JSON5 config file.")] = None,
    run_id: Annotated[str | None, typer.Option("--run", help="Run name in key expressions.")] = None,
    live: Annotated[bool | None, typer.Option("--live/--no-live", help="Live view (default: on a terminal).")] = None,
) -> None:
    """The monitor process: records states, beacons and topology events of a distributed run."""
    try:
        from monitor.process import MonitorConfig, run
        from reconswarm.net.session import ZenohOptions, bind_to_parent, setup_logging

        setup_logging()
        bind_to_parent()

        code = run(MonitorConfig(scenario, db, ZenohOptions.build(connect, listen, mode, zenoh_config), run_id,
                                 live if live is not None else sys.stderr.isatty()))
    except ReconswarmError as exc:
        fail(exc)
        return
    raise typer.Exit(code)
