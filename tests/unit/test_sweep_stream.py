"""The sweep's job stream: lazy (a plan of 10^8 seeds is not built), bounded in flight, rows in order."""

from __future__ import annotations

import csv
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from reconswarm_bringup import sweep as sw


def _plan(tmp_path: Path, seeds: range) -> sw.JobPlan:
    path = tmp_path / "g.toml"
    path.write_text(to_toml(generate(3, 1, 1)))
    return sw.JobPlan([path], seeds, ("reconfigurable", "virtual-leader"), tmp_path / "out")


def test_a_plan_of_a_hundred_million_seeds_is_lazy(tmp_path: Path) -> None:
    plan = _plan(tmp_path, range(0, 100_000_000))
    assert len(plan) == 200_000_000
    it = iter(plan)
    first, second = next(it), next(it)
    assert (first.scenario.meta.seed, second.scenario.meta.seed) == (0, 1)
    assert first.scenario.planner.kind == "reconfigurable"
    assert first.out_dir.endswith("runs/g/reconfigurable/seed0")


class _Counting(ThreadPoolExecutor):
    """Runs a stand-in for run_one and records the most futures ever in flight."""

    def __init__(self) -> None:
        super().__init__(2)
        self.lock = threading.Lock()
        self.in_flight = 0
        self.most = 0

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> Future[Any]:
        job = args[0]
        with self.lock:
            self.in_flight += 1
            self.most = max(self.most, self.in_flight)

        def fake() -> dict[str, Any]:
            with self.lock:
                self.in_flight -= 1
            return {"scenario": job.label, "planner": job.scenario.planner.kind, "seed": job.scenario.meta.seed}

        return super().submit(fake)


def test_stream_keeps_at_most_the_window_in_flight(tmp_path: Path) -> None:
    plan = _plan(tmp_path, range(0, 10**8))
    ex = _Counting()
    got = []
    with ex:
        for i, _job, row in sw.stream(plan, ex, 4):
            got.append((i, row["seed"]))
            if len(got) == 50:
                break
    assert ex.most <= 4
    assert sorted(i for i, _ in got) == sorted(set(i for i, _ in got))
    assert all(seed == i for i, seed in got)  # index i of the reconfigurable block is seed i


def _row(planner: str, seed: int) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(sw.COLUMNS, 0)
    row.update(scenario="g.toml", planner=planner, seed=seed, converged=True, convergence_time_s=float(seed))
    return row


def test_results_file_truncates_appends_and_finishes_in_job_order(tmp_path: Path) -> None:
    path = tmp_path / "results.csv"
    path.write_text("scenario\nstale\nstale\n")
    res = sw.ResultsFile(path)
    assert path.read_text().splitlines() == [",".join(sw.COLUMNS)]  # the stale file is gone at once
    for i in (2, 0, 1):
        res.add(i, _row("reconfigurable", i))
        with path.open(newline="") as f:  # each row is on disk as soon as it is added
            assert len(list(csv.reader(f))) == 1 + res.rows
    res.finish()
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["seed"] for r in rows] == ["0", "1", "2"]


def test_stats_accumulated_equal_stats_of_the_rows() -> None:
    rows = [_row("a", s) for s in range(7)] + [_row("b", 3)]
    rows[2]["converged"] = False
    rows[4]["collisions"] = 2
    acc = sw.Stats()
    for r in rows:
        acc.add(r)
    assert acc.result() == sw.planner_stats(rows)
    a = acc.result()[0]
    assert (a["scenario"], a["planner"]) == ("g.toml", "a")
    assert a["converged"] == 6 and a["contacts"] == 2
    assert a["convergence_median_s"] == 3.5  # median of 0, 1, 3, 4, 5, 6


def test_the_table_has_a_line_per_scenario_and_planner_never_pooling_scenarios() -> None:
    rows = [_row("a", s) for s in range(3)] + [{**_row("a", s), "scenario": "h.toml", "convergence_time_s": 10.0 + s}
                                               for s in range(3)]
    table = sw.planner_stats(rows)
    assert [(t["scenario"], t["planner"]) for t in table] == [("g.toml", "a"), ("h.toml", "a")]
    assert [t["convergence_median_s"] for t in table] == [1.0, 11.0]  # (pooled, the median would be 6.0)


def test_seeds_that_changed_nothing_are_said_once_per_scenario() -> None:
    same = [{**_row(k, s), "convergence_time_s": 5.0, "wall_time_s": 0.1 * s} for k in ("a", "b") for s in range(3)]
    differ = [{**_row("a", s), "scenario": "h.toml"} for s in range(3)]  # convergence time = seed
    one = [{**_row("a", 0), "scenario": "k.toml"}]  # a single seed: nothing to say
    st = sw.Stats()
    for r in same + differ + one:
        st.add(r)
    assert st.seed_without_effect() == {"g.toml": [("a", 3), ("b", 3)]}
    (note,) = sw.seed_notes(st)
    assert note.startswith("sweep: g.toml: its 3 seeds gave one and the same row (a, b)") and "\n" not in note
    assert "deadlock perturbation" in note


def test_clashing_stems_never_share_a_record_directory(tmp_path: Path) -> None:
    """a/x.toml and b/x.toml share a stem; c/x-2.toml's own stem is what b's suffix would be."""
    paths = []
    for sub in ("a", "b", "c"):
        (tmp_path / sub).mkdir()
        paths.append(tmp_path / sub / ("x-2.toml" if sub == "c" else "x.toml"))
        paths[-1].write_text(to_toml(generate(3, 1, 1)))
    jobs = sw.make_jobs(paths, range(0, 1), ("reconfigurable", "virtual-leader"), tmp_path / "out")
    assert len(jobs) == 6 and len({j.out_dir for j in jobs}) == 6
    runs = tmp_path / "out" / "runs"
    by_file = {j.label: Path(j.out_dir).relative_to(runs).parts[0] for j in jobs}
    assert by_file[str(paths[0])] == "x" and by_file[str(paths[2])] == "x-2"  # a file's own stem kept
    assert by_file[str(paths[1])] not in ("x", "x-2")
