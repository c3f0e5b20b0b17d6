"""`reconswarm sweep`: every scenario x seed x planner, one in-process engine run each, in parallel.

The runs are independent, so the runner is written against `concurrent.futures.Executor` alone:
`run_one(job) -> row` is a pure, picklable module-level function of a frozen `Job` (the parsed
scenario travels inside the job, so a worker needs no access to the scenario files), and `stream`
only calls `executor.submit`. A `ProcessPoolExecutor` (the command's default), a `ThreadPoolExecutor`,
Dask's `distributed.Client(...).get_executor()` (`--dask`, sweep_exec.py), or a few lines around Ray
(`submit` returning `ray.remote(run_one).remote(job).future()`) all fit (docs/sweeps.md).
Jobs are generated lazily (`JobPlan`) and only a window of them is in flight, so a sweep's memory does
not grow with its size; rows go to results.csv as runs finish (`ResultsFile`), the table accumulates
(`Stats`). Each run writes its record (run.db) under the job's `out_dir`, on the worker's file system.
"""

from __future__ import annotations

import csv
import math
import os
from array import array
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from reconswarm.errors import BadInput
from reconswarm.planners import registry
from reconswarm.scenario.model import PLANNERS, Scenario, load
from reconswarm_bringup import engine

COLUMNS = ("scenario", "planner", "seed", "converged", "convergence_time_s", "final_max_error_m", "collisions",
           "safety_violations", "min_agent_gap_m", "min_obstacle_gap_m", "splits", "merges", "path_length_mean_m",
           "wall_time_s")
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


def record_names(paths: Sequence[Path]) -> list[str]:
    """Each file's directory under runs/, all distinct: its stem, for the first file of that stem; a later file
    of a stem already taken gets `<stem>-2`, `-3`, ..., skipping every name another file has as its own stem
    (a/x.toml, b/x.toml, c/x-2.toml -> x, x-3, x-2)."""
    own = {p.stem for p in paths}
    taken: set[str] = set()
    names = []
    for p in paths:
        name, n = p.stem, 1
        while name in taken:  # (a suffixed name is never a file's own stem: that file's first one stays free)
            n += 1
            name = f"{p.stem}-{n}"
            if name in own:
                name = p.stem
        taken.add(name)
        names.append(name)
    return names


class JobPlan:
    """The jobs of a sweep, generated lazily (a sweep of 10^8 seeds holds one job at a time, not 10^8):
    scenario-major, then planner, then seed. Records go to out_dir/runs/<name>/<planner>/seed<S>, <name> being
    the file's stem (`record_names`). Each file is loaded (and checked) once, up front."""

    def __init__(self, paths: Sequence[Path], seeds: range | None, planners: Sequence[str] | None,
                 out_dir: Path) -> None:
        self.out_dir = out_dir
        self.seeds = seeds
        self.files: list[tuple[str, str, Scenario]] = []  # (label, record name, scenario)
        for path, name in zip(paths, record_names(paths), strict=True):
            # BadInput naming the file and field (the engine uses no wire)
            base = load(path, wire=False)
            self.files.append((str(path), name, base))
            for kind in planners or (base.planner.kind,):  # an optional dependency missing: refused up front
                registry.require(base.with_planner(kind))
        self.planners = planners

    def __len__(self) -> int:
        kinds = len(self.planners) if self.planners else 1
        return len(self.files) * kinds * (len(self.seeds) if self.seeds is not None else 1)

    def __iter__(self) -> Iterator[Job]:
        for label, stem, base in self.files:
            for kind in self.planners or (base.planner.kind,):
                for seed in self.seeds if self.seeds is not None else (base.meta.seed,):
                    s = base.with_planner(kind).with_seed(seed)
                    yield Job(label, s, str(self.out_dir / "runs" / stem / kind / f"seed{seed}"))


def make_jobs(paths: Sequence[Path], seeds: range | None, planners: Sequence[str] | None,
              out_dir: Path) -> list[Job]:
    """Every job of a small sweep as a list (JobPlan's order)."""
    return list(JobPlan(paths, seeds, planners, out_dir))


def run_one(job: Job) -> Row:
    """Run one job with the in-process engine and return its results row (the COLUMNS)."""
    summary = engine.run(engine.SimConfig(job.scenario, Path(job.out_dir), progress=False))
    row = {k: path_length_mean_m(summary) if k == "path_length_mean_m" else summary[k] for k in COLUMNS}
    row["scenario"] = job.label
    row["planner"] = job.scenario.planner.kind
    row["seed"] = job.scenario.meta.seed
    return row


def path_length_mean_m(summary: dict[str, Any]) -> float:
    """The metres each agent's head point travelled (the summary's path_length_m), averaged over the agents."""
    paths = list(summary["path_length_m"].values())
    return round(sum(paths) / len(paths), 2) if paths else 0.0


def stream(jobs: Iterable[Job], executor: Executor, window: int, check: Callable[[], None] | None = None,
           every_s: float = 1.0) -> Iterator[tuple[int, Job, Row]]:
    """Submit the jobs with at most `window` in flight; yield (job index, job, row) as each run finishes.
    A failed run raises its exception here; so does `check()`, called every `every_s` while runs are under
    way (an executor that can lose its workers says so there); on any exception (KeyboardInterrupt included)
    the runs not started are cancelled."""
    todo = enumerate(jobs)
    pending: dict[Future[Row], tuple[int, Job]] = {}
    try:
        while True:
            while len(pending) < max(1, window):
                nxt = next(todo, None)
                if nxt is None:
                    break
                pending[executor.submit(run_one, nxt[1])] = nxt
            if not pending:
                return
            done, _ = wait(pending, timeout=None if check is None else every_s, return_when=FIRST_COMPLETED)
            if check is not None:
                check()
            for fut in done:
                i, job = pending.pop(fut)
                yield i, job, fut.result()
    finally:
        for fut in pending:
            fut.cancel()


def run_sweep(jobs: Sequence[Job], executor: Executor,
              on_done: Callable[[Job, Row], None] | None = None) -> list[Row]:
    """Run every job; return the rows in job order. on_done(job, row) is called in this process as each
    run finishes (for a progress bar). A failed run raises its exception here."""
    rows: list[Row | None] = [None] * len(jobs)
    for i, job, row in stream(jobs, executor, len(jobs)):
        rows[i] = row
        if on_done is not None:
            on_done(job, row)
    return [r for r in rows if r is not None]


def percentile(values: Sequence[float], q: float) -> float | None:
    """The q-th percentile (numpy's linear interpolation between order statistics), None if empty."""
    return float(np.percentile(np.asarray(values, dtype=np.float64), q)) if values else None


SAME = tuple(c for c in COLUMNS if c not in ("seed", "wall_time_s"))  # what a seed could change in a row


class _Group:
    """One scenario x planner's runs so far: [runs, converged, contacts], the convergence times, and whether
    every run's row equals the first's but for seed and wall time."""

    def __init__(self) -> None:
        self.counts = [0, 0, 0]
        self.times: array[float] = array("d")
        self.first: tuple[Any, ...] | None = None
        self.identical = True


class Stats:
    """The table, one line per scenario x planner (a scenario's runs are never pooled with another's),
    accumulated as rows come (the rows themselves need not be kept): runs, converged, median and p90 of the
    convergence time over the converged runs, contacts (collision episodes summed over the runs); in order of
    first appearance. Also which scenarios' seeds changed nothing (`seed_without_effect`)."""

    def __init__(self) -> None:
        self._by: dict[tuple[str, str], _Group] = {}  # (scenario, planner) -> its runs

    def add(self, row: Row) -> None:
        g = self._by.setdefault((row["scenario"], row["planner"]), _Group())
        g.counts[0] += 1
        g.counts[2] += int(row["collisions"])
        if row["converged"]:
            g.counts[1] += 1
            g.times.append(float(row["convergence_time_s"]))
        sig = tuple(row[c] for c in SAME)
        if g.first is None:
            g.first = sig
        elif sig != g.first:
            g.identical = False

    def result(self) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = []
        for (scenario, kind), g in self._by.items():
            med, p90 = percentile(g.times, 50), percentile(g.times, 90)
            out.append({"scenario": scenario, "planner": kind, "runs": g.counts[0], "converged": g.counts[1],
                        "convergence_median_s": None if med is None else round(med, 3),
                        "convergence_p90_s": None if p90 is None else round(p90, 3),
                        "contacts": g.counts[2]})
        return out

    def seed_without_effect(self) -> dict[str, list[tuple[str, int]]]:
        """scenario -> (planner, runs) for each of its planners whose runs (two seeds or more) all gave the same
        row but for seed and wall time: the seed drives only the deadlock perturbation, so where no agent
        stalls it changes nothing, and those runs are one sample, not several."""
        out: dict[str, list[tuple[str, int]]] = {}
        for (scenario, kind), g in self._by.items():
            if g.counts[0] > 1 and g.identical:
                out.setdefault(scenario, []).append((kind, g.counts[0]))
        return out


def planner_stats(rows: Iterable[Row]) -> list[dict[str, Any]]:
    """Stats over the rows (see Stats): one entry per scenario x planner."""
    st = Stats()
    for r in rows:
        st.add(r)
    return st.result()


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


class ResultsFile:
    """results.csv written as the sweep goes: truncated to its header when the sweep starts (a previous
    sweep's rows never pass for this one's), each run's row appended and flushed as the run finishes (an
    interrupted sweep keeps a row for every finished run). `finish()`, for a sweep that ran to its end,
    puts the rows in job order (the order of a sweep does not depend on which worker finished first)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self._f = path.open("w", newline="")
        self._w = csv.writer(self._f)
        self._w.writerow(COLUMNS)
        self._f.flush()
        self._order = array("q")  # the job index of each row written
        self.rows = 0

    def add(self, index: int, row: Row) -> None:
        self._w.writerow([_cell(row[c]) for c in COLUMNS])
        self._f.flush()
        self._order.append(index)
        self.rows += 1

    def close(self) -> None:
        self._f.close()

    def finish(self) -> None:
        self.close()
        order = list(self._order)
        if order == sorted(order):
            return
        with self.path.open(newline="") as f:
            rd = csv.reader(f)
            header = next(rd)
            lines = [line for _, line in sorted(zip(order, rd, strict=True), key=lambda p: p[0])]
        tmp = self.path.with_name(self.path.name + ".tmp")
        with tmp.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(header)
            w.writerows(lines)
        os.replace(tmp, self.path)


def _sec(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def render_stats(stats: list[dict[str, Any]]) -> Any:
    """A rich Table: one line per scenario x planner."""
    from rich.table import Table

    table = Table(title="reconswarm sweep", show_header=True)
    table.add_column("scenario", overflow="fold")  # (a long path wraps in its cell, whole)
    table.add_column("planner", no_wrap=True, min_width=max(map(len, PLANNERS)))
    for name in ("runs", "converged", "median (s)", "p90 (s)", "contacts"):
        table.add_column(name, justify="right", no_wrap=True)
    for st in stats:
        rate = 100.0 * st["converged"] / st["runs"]
        table.add_row(st["scenario"], st["planner"], str(st["runs"]), f"{st['converged']} ({rate:.0f} %)",
                      _sec(st["convergence_median_s"]), _sec(st["convergence_p90_s"]), str(st["contacts"]))
    return table


def seed_notes(stats: Stats) -> list[str]:
    """One line per scenario whose seeds changed nothing (Stats.seed_without_effect)."""
    notes = []
    for scenario, groups in stats.seed_without_effect().items():
        n = max(runs for _, runs in groups)
        notes.append(f"sweep: {scenario}: its {n} seeds gave one and the same row "
                     f"({', '.join(kind for kind, _ in groups)}): the seed drives only the deadlock perturbation "
                     f"(the side a stalled agent escapes by), so these are one sample, not {n}")
    return notes
