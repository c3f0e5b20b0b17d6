"""`reconswarm sweep`: every scenario x seed x planner, one in-process engine run each, in parallel.

The runs are independent, so the runner is written against `concurrent.futures.Executor` alone:
`run_one(job) -> row` is a pure, picklable module-level function of a frozen `Job` (the parsed
scenario travels inside the job, so a worker needs no access to the scenario files), and
`run_sweep(jobs, executor)` only calls `executor.submit`. A `ProcessPoolExecutor` (the command's
default), a `ThreadPoolExecutor`, Dask's `distributed.Client(...).get_executor()`, or a few lines
around Ray (`submit` returning `ray.remote(run_one).remote(job).future()`) all fit (README, "Sweeps").
Each run writes its record (run.db) under the job's `out_dir`, on the worker's file system.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Executor, Future, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from reconswarm.errors import BadInput
from reconswarm.scenario import PLANNERS, Scenario, load
from reconswarm_bringup import engine

COLUMNS = ("scenario", "planner", "seed", "converged", "convergence_time_s", "final_max_error_m", "collisions",
           "safety_violations", "min_agent_gap_m", "min_obstacle_gap_m", "splits", "merges", "wall_time_s")
STATS = ("runs", "converged", "convergence_median_s", "convergence_p90_s", "contacts")

Row = dict[str, Any]


@dataclass(frozen=True)
class Job:
    """One run: the scenario with its planner and seed already applied, its label for the results (the
    scenario as named on the command line), and where the run's record goes."""

    label: str
    scenario: Scenario
    out_dir: str


def parse_seeds(text: str | None) -> range | None:
    """`A:B` -> range(A, B) (A inclusive, B exclusive, 0 <= A < B); None -> each file's own seed."""
    if text is None:
        return None
    a, sep, b = text.partition(":")
    try:
        lo, hi = int(a), int(b)
    except ValueError:
        lo = hi = -1
    if not sep or lo < 0 or hi <= lo:
        raise BadInput(f"--seeds: expected A:B with 0 <= A < B (A inclusive, B exclusive), got {text!r}")
    return range(lo, hi)


def parse_planners(text: str | None) -> tuple[str, ...] | None:
    """`P[,P...]` -> the planner kinds, each checked; None -> each file's own planner."""
    if text is None:
        return None
    kinds = tuple(k.strip() for k in text.split(","))
    for k in kinds:
        if k not in PLANNERS:
            raise BadInput(f"--planner: unknown planner {k!r} (expected one of {', '.join(PLANNERS)})")
    if len(set(kinds)) != len(kinds):
        raise BadInput(f"--planner: a planner is listed twice in {text!r}")
    return kinds


def make_jobs(paths: Sequence[Path], seeds: range | None, planners: Sequence[str] | None,
              out_dir: Path) -> list[Job]:
    """The jobs of a sweep, scenario-major, then planner, then seed. Records go to
    out_dir/runs/<file stem>/<planner>/seed<S> (a stem repeated across directories gets a suffix)."""
    jobs: list[Job] = []
    stems: dict[str, int] = {}
    for path in paths:
        base = load(path)  # BadInput naming the file and field
        stem = path.stem
        stems[stem] = stems.get(stem, 0) + 1
        if stems[stem] > 1:
            stem = f"{stem}-{stems[stem]}"
        for kind in planners or (base.planner.kind,):
            for seed in seeds if seeds is not None else (base.meta.seed,):
                s = base.with_planner(kind).with_seed(seed)
                jobs.append(Job(str(path), s, str(out_dir / "runs" / stem / kind / f"seed{seed}")))
    return jobs


def run_one(job: Job) -> Row:
    """Run one job with the in-process engine and return its results row (the COLUMNS)."""
    summary = engine.run(engine.SimConfig(job.scenario, Path(job.out_dir), progress=False))
    row = {k: summary[k] for k in COLUMNS}
    row["scenario"] = job.label
    row["planner"] = job.scenario.planner.kind
    row["seed"] = job.scenario.meta.seed
    return row


def run_sweep(jobs: Sequence[Job], executor: Executor,
              on_done: Callable[[Job, Row], None] | None = None) -> list[Row]:
    """Submit every job to the executor; return the rows in job order. on_done(job, row) is called in
    this process as each run finishes (for a progress bar). A failed run raises its exception here."""
    futures: dict[Future[Row], int] = {executor.submit(run_one, job): i for i, job in enumerate(jobs)}
    rows: list[Row | None] = [None] * len(jobs)
    try:
        for fut in as_completed(futures):
            i = futures[fut]
            rows[i] = fut.result()
            if on_done is not None:
                on_done(jobs[i], rows[i])  # type: ignore[arg-type]
    except BaseException:
        for fut in futures:
            fut.cancel()
        raise
    return [r for r in rows if r is not None]


def percentile(values: Sequence[float], q: float) -> float | None:
    """The q-th percentile (numpy's linear interpolation between order statistics), None if empty."""
    return float(np.percentile(np.asarray(values, dtype=np.float64), q)) if values else None


def planner_stats(rows: Iterable[Row]) -> dict[str, dict[str, Any]]:
    """Per planner (in order of first appearance): runs, converged, median and p90 of the convergence
    time over the converged runs, contacts (collision episodes summed over the runs)."""
    by: dict[str, list[Row]] = {}
    for r in rows:
        by.setdefault(r["planner"], []).append(r)
    out: dict[str, dict[str, Any]] = {}
    for kind, rs in by.items():
        times = [float(r["convergence_time_s"]) for r in rs if r["converged"]]
        med, p90 = percentile(times, 50), percentile(times, 90)
        out[kind] = {"runs": len(rs), "converged": sum(1 for r in rs if r["converged"]),
                     "convergence_median_s": None if med is None else round(med, 3),
                     "convergence_p90_s": None if p90 is None else round(p90, 3),
                     "contacts": sum(int(r["collisions"]) for r in rs)}
    return out


def _cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, float) and math.isfinite(v):
        return repr(v)
    return v


def write_csv(rows: Iterable[Row], path: Path) -> None:
    """results.csv: a header of COLUMNS, one row per run; an absent value (no convergence time, no gap
    measured) is an empty cell."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow([_cell(r[c]) for c in COLUMNS])


def _sec(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def render_stats(stats: dict[str, dict[str, Any]]) -> Any:
    """A rich Table: one line per planner."""
    from rich.table import Table

    table = Table(title="reconswarm sweep", show_header=True)
    for name, justify in (("planner", "left"), ("runs", "right"), ("converged", "right"),
                          ("median (s)", "right"), ("p90 (s)", "right"), ("contacts", "right")):
        table.add_column(name, justify=justify)  # type: ignore[arg-type]
    for kind, st in stats.items():
        rate = 100.0 * st["converged"] / st["runs"]
        table.add_row(kind, str(st["runs"]), f"{st['converged']} ({rate:.0f} %)", _sec(st["convergence_median_s"]),
                      _sec(st["convergence_p90_s"]), str(st["contacts"]))
    return table
