"""`reconswarm sweep`: every scenario x seed x planner with the in-process engine, on local worker processes
or a Dask cluster. Jobs are generated as they are submitted (a few in flight per worker), each run's row is
appended to DIR/results.csv as it finishes, and however the sweep ends it says how many rows are in."""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Annotated, Any

import typer

from reconswarm.cli import outputs
from reconswarm.cli.console import fail, print_json
from reconswarm.errors import BadInput, ProcessFailure, ReconswarmError


def outcome(row: dict[str, Any]) -> str:
    """A run's outcome for the progress line: not converging is an outcome of the mission, not a failure."""
    if row["collisions"]:
        return f"{row['collisions']} collision(s)"
    return "converged" if row["converged"] else "not converged"


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Iterator[list[int]]:
    """SIGINT and SIGTERM both stop the sweep as Ctrl-C does; yields the list the signal number goes to."""
    got: list[int] = []

    def handler(signum: int, _frame: Any) -> None:
        got.append(signum)
        raise KeyboardInterrupt

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield got
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


def sweep_cmd(
    scenarios: Annotated[list[Path], typer.Argument(metavar="SCENARIO...", help="Scenario TOML files.")],
    out: Annotated[Path, typer.Option("-o", "--out", metavar="DIR", help="Output directory (results.csv, runs/).")],
    seeds: Annotated[str | None, typer.Option("--seeds", metavar="A:B",
        help="Seeds A..B-1 (default: each file's seed). The seed drives only the deadlock perturbation (the "
             "side a stalled agent escapes by): where no agent stalls, every seed gives the same run, and the "
             "sweep says so.")] = None,
    planner: Annotated[str | None, typer.Option("--planner", metavar="P[,P...]",
        help="reconfigurable, virtual-leader, orca, hrvo, hl, social-force (default: each file's planner).")] = None,
    jobs: Annotated[int | None, typer.Option("--jobs", "-j", metavar="J",
        help="Parallel processes (default: cores).")] = None,
    dask_address: Annotated[str | None, typer.Option("--dask", metavar="ADDRESS",
        help="Run on the Dask cluster whose scheduler is at ADDRESS (tcp://host:port) instead.")] = None,
    as_json: Annotated[bool, typer.Option("--json",
        help="Print the rows and the table (per scenario x planner) as JSON.")] = False,
    plot: Annotated[Path | None, typer.Option("--plot", metavar="FILE.png",
        help="Also draw success and convergence time by planner, one column per suite (scenario directory).")] = None,
) -> None:
    """Every scenario x seed x planner with the in-process engine, in parallel; results.csv and a table per
    scenario x planner."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from reconswarm_bringup import sweep as sw
    from reconswarm_bringup import sweep_exec

    try:
        if jobs is not None and jobs < 1:
            raise BadInput(f"--jobs: must be >= 1, got {jobs}")
        if jobs is not None and dask_address is not None:
            raise BadInput("--jobs and --dask: give one (a Dask cluster runs as many runs as its workers have threads)")
        seed_range = sw.parse_seeds(seeds)
        kinds = sw.parse_planners(planner)
        for path in scenarios:
            if not path.is_file():
                raise BadInput(f"{path}: no such scenario file")
        if plot is not None and plot.suffix.lower() != ".png":
            raise BadInput(f"--plot: expected a .png file, got {str(plot)!r}")
        plan = sw.JobPlan(scenarios, seed_range, kinds, out)
        total = len(plan)
        outputs.writable_dir("-o", out)
    except (ReconswarmError, OSError) as exc:
        fail(exc)
        return
    if dask_address is None:
        workers = max(1, min(jobs or os.cpu_count() or 1, total))
        where, where_txt = sweep_exec.local(workers), f"{workers} processes"
    else:
        where, where_txt = sweep_exec.dask(dask_address), f"on the Dask cluster at {dask_address}"
    bar = Progress(TextColumn("sweep"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[last]}"),
                   TimeElapsedColumn(), console=Console(stderr=True), transient=True)
    task = bar.add_task("sweep", total=total, last="")
    stats = sw.Stats()
    kept: list[tuple[int, dict[str, Any]]] = []  # only for --json
    results: sw.ResultsFile | None = None
    problem: BaseException | None = None
    with _sigterm_as_interrupt() as signals:
        try:
            with where as (executor, slots, check):
                results = sw.ResultsFile(out / "results.csv")  # truncated now: no stale rows of another sweep
                with bar:
                    for i, _job, row in sw.stream(plan, executor, 2 * slots, check):
                        results.add(i, row)
                        stats.add(row)
                        if as_json:
                            kept.append((i, row))
                        bar.update(task, advance=1, last=f"{Path(row['scenario']).name} {row['planner']} "
                                                         f"seed {row['seed']}: {outcome(row)}")
        except BaseException as exc:  # Ctrl-C or SIGTERM, a run that failed, a worker that died, no scheduler
            problem = exc
    if problem is not None:
        interrupted = isinstance(problem, KeyboardInterrupt)
        if results is not None:
            results.close()
        stopped = None
        if results is not None and (interrupted or results.rows):
            stopped = (f"stopped after {results.rows} of {total} runs; {out / 'results.csv'} holds "
                       f"their {results.rows} rows")
        if interrupted:
            if stopped:
                typer.echo(f"sweep: {stopped}", err=True)
            raise typer.Exit(128 + (signals[0] if signals else signal.SIGINT))
        if isinstance(problem, BrokenProcessPool):
            problem = ProcessFailure(f"sweep: a worker process died ({problem})")
        elif not isinstance(problem, ReconswarmError | OSError):
            problem = ProcessFailure(f"sweep: a run failed ({type(problem).__name__}: {problem})")
        if stopped:  # one line: what ended the sweep, and what it leaves
            problem = (type(problem) if isinstance(problem, ReconswarmError) else ReconswarmError)(
                f"{problem}; {stopped}")
        fail(problem)
        return
    assert results is not None
    results.finish()
    if plot is not None:
        from reconswarm_bringup.sweep_plot import plot as draw

        try:
            draw(out / "results.csv", plot)
        except (ReconswarmError, OSError) as exc:
            fail(exc)
            return
        typer.echo(f"plot: {plot}", err=True)
    if as_json:
        print_json({"rows": [r for _, r in sorted(kept, key=lambda p: p[0])], "table": stats.result()})
    else:
        Console().print(sw.render_stats(stats.result()))
        typer.echo(f"results: {out / 'results.csv'} ({results.rows} runs, {where_txt})")
    for note in sw.seed_notes(stats):
        typer.echo(note, err=True)


def register(app: typer.Typer) -> None:
    app.command("sweep")(sweep_cmd)
