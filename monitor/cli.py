"""`reconswarm monitor ...` (= `python -m monitor ...`): commands that read a run record (and `record`, the live
monitor process). reconswarm_bringup/cli.py registers `monitor_app` as the `monitor` group."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

from reconswarm.cli import help_style, outputs
from reconswarm.cli.console import fail, print_json
from reconswarm.errors import BadInput, ReconswarmError

help_style.install()

monitor_app = typer.Typer(no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
                          help="Record runs and read run records (run.db).")

DbArg = Annotated[Path, typer.Argument(metavar="RUN.DB", help="A run record (run.db).")]


def _open(db: Path) -> Any:
    from reconswarm.record.store import RunRecord

    return RunRecord(db)


@monitor_app.command("summary")
def summary_cmd(db: DbArg, as_json: Annotated[bool, typer.Option("--json", help="Print it as JSON.")] = False) -> None:
    """The run summary: outcome, convergence, safety, topology, timing and membership of the run."""
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
def events_cmd(db: DbArg, as_json: Annotated[bool, typer.Option("--json", help="Print them as JSON.")] = False) -> None:
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
    fmt: Annotated[str, typer.Option("--format", help="csv | mcap")] = "csv",
    out: Annotated[Path | None, typer.Option("-o", "--out", help="File to write (csv: default stdout).")] = None,
    period_s: Annotated[float | None, typer.Option(
        "--period", help="mcap: seconds of simulated time between scenes, at most 1 (default: every tick "
                         "if that draws at most 500k agents in all, else 0.1, 0.2, 0.5 or 1 s).")] = None,
) -> None:
    """csv: trajectories t_s,agent,px_m,py_m,theta_rad, one row per agent per tick. mcap: the run for
    Foxglove (a SceneUpdate scene, per-agent tracking error, events as Log, the scenario attached)."""
    try:
        if fmt not in ("csv", "mcap"):
            raise BadInput(f"--format: unsupported format {fmt!r} (csv or mcap)")
        if fmt == "mcap":
            if out is None:
                raise BadInput("--format mcap: give the file to write with -o FILE.mcap")
            outputs.not_the_input("-o", out, db)
            outputs.writable_file("-o", out)
            from monitor.mcap_export import export_mcap

            rec = _open(db)
            with _progress_bar(f"exporting {db}") as progress:
                stats = export_mcap(rec, out, period_s, progress)
            rec.close()
            every = "every tick" if stats.period_s is None else f"every {stats.period_s:g} s"
            typer.echo(f"wrote {out}: {stats.bytes / 1e6:.1f} MB, {stats.scene_messages} scenes ({every}), "
                       f"{stats.events} events")
            return
        if out is not None:
            outputs.not_the_input("-o", out, db)
            outputs.writable_file("-o", out)
        from monitor.csv_export import export_csv

        rec = _open(db)
        ticks = rec.ticks()  # a damaged record: one line, exit 2, before -o FILE is created or stdout written
        stream = sys.stdout if out is None else _open_out(out)
    except ReconswarmError as exc:
        fail(exc)
        return
    try:
        with _progress_bar(f"exporting {db}") as progress:
            rows = export_csv(rec, stream, progress, ticks)
    finally:
        rec.close()
        if out is not None:
            stream.close()
    if out is not None:
        typer.echo(f"wrote {out}: {rows} rows")


def _open_out(out: Path) -> Any:
    try:
        return out.open("w", newline="")
    except OSError as exc:
        raise BadInput(f"{out}: cannot write ({exc.strerror})") from None


@contextmanager
def _progress_bar(label: str, counted: bool = True) -> Iterator[Callable[[int, int], None] | None]:
    """A rich progress bar on a terminal (stderr), else nothing: yields progress(done, total) or None.
    Not counted: the bar pulses with the elapsed time (a step with no parts to count, as drawing a figure)."""
    if not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        ProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    cols: list[ProgressColumn] = [TextColumn(label), BarColumn()]
    cols += [MofNCompleteColumn(), TimeRemainingColumn()] if counted else [TimeElapsedColumn()]
    bar = Progress(*cols, console=Console(stderr=True), transient=True)
    task = bar.add_task(label, total=None)
    with bar:
        yield lambda done, total: bar.update(task, completed=done, total=total)


@monitor_app.command("animate")
def animate_cmd(
    db: DbArg,
    out: Annotated[Path, typer.Option("-o", "--out", help="FILE.gif (Pillow) or FILE.mp4 (needs ffmpeg).")],
    fps: Annotated[int, typer.Option("--fps", help="Frames per second of the animation (1..50).")] = 10,
    speed: Annotated[float, typer.Option("--speed", help="Simulated seconds per second of animation.")] = 20.0,
    dpi: Annotated[float, typer.Option("--dpi", help="Resolution (the frame is 8 x 6.2 inches).")] = 72.0,
    at_s: Annotated[float | None, typer.Option(
        "--at", help="Write only the frame at this simulated time, as a PNG (-o FILE.png).")] = None,
) -> None:
    """The run as an animation (paper Fig. 4 in motion): the mission with every track, and a window that
    follows the swarm with agents to scale coloured by group, links, slots and obstacles."""
    try:
        from monitor.animate import animate_run, check_request

        outputs.not_the_input("-o", out, db)
        if at_s is None:
            check_request(out, fps, speed)  # before opening the record: bad requests fail fast
        elif out.suffix.lower() != ".png":
            raise BadInput(f"{out}: --at writes one frame as a PNG (-o FILE.png)")
        outputs.writable_file("-o", out)
        rec = _open(db)
        with _progress_bar(f"animating {db}") as progress:
            stats = animate_run(rec, out, fps, speed, dpi, progress, still_at_s=at_s)
        rec.close()
    except ReconswarmError as exc:
        fail(exc)
        return
    if at_s is None:
        typer.echo(f"wrote {out}: {stats.frames} frames at {fps:g} fps ({speed:g}x), {stats.bytes / 1e6:.2f} MB")
    else:
        typer.echo(f"wrote {out}")


@monitor_app.command("plot")
def plot_cmd(
    db: DbArg,
    out: Annotated[Path, typer.Option("-o", "--out", help="PNG file to write.")],
) -> None:
    """Trajectories with obstacles and slots coloured by group, snapshot panels (paper Fig. 4) and the
    tracking error of every agent over time (Fig. 5)."""
    try:
        from monitor.plot import plot_run

        outputs.not_the_input("-o", out, db)
        outputs.writable_file("-o", out)
        rec = _open(db)
        with _progress_bar(f"plotting {db}", counted=False):  # (nothing to count: it pulses while drawing)
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
    foxglove: Annotated[int | None, typer.Option("--foxglove", metavar="PORT",
        help="Also serve the run to the Foxglove app on ws://127.0.0.1:PORT (0: any free port).")] = None,
) -> None:
    """The monitor process of a distributed run: records the world's truth and clock, the agents' reports,
    membership changes and the topology events (it does not hear the agents' beacons)."""
    try:
        from monitor.process import MonitorConfig, run
        from reconswarm.cli.options import profiled
        from reconswarm.net.runtime.lifecycle import bind_to_parent, setup_logging
        from reconswarm.net.runtime.session import ZenohOptions

        setup_logging()
        bind_to_parent()

        if foxglove is not None and not 0 <= foxglove <= 65535:
            raise BadInput(f"--foxglove: port must be in 0..65535, got {foxglove}")
        outputs.writable_file("--db", db)
        with profiled("monitor.cli"):
            code = run(MonitorConfig(scenario, db, ZenohOptions.build(connect, listen, mode, zenoh_config), run_id,
                                     live if live is not None else sys.stderr.isatty(), foxglove))
    except ReconswarmError as exc:
        fail(exc)
        return
    raise typer.Exit(code)
