"""`reconswarm sweep`: the CSV and the table of a small real sweep (worker processes), checked against
the engine run directly, and the runner on another Executor."""

from __future__ import annotations

import csv
import json
import math
import re
import statistics
import subprocess
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import load, to_toml
from reconswarm_bringup import engine
from reconswarm_bringup.cli import app
from reconswarm_bringup.sweep import COLUMNS, make_jobs, path_length_mean_m, run_sweep
from tests.support import reconswarm

pytestmark = pytest.mark.parallel  # (no launch, no router, no wall-clock bound: beside the unit tests)

PLANNERS = ("reconfigurable", "virtual-leader")
SEEDS = (0, 1)
# Two tiny generated scenarios cut short: at 170 s every run of the first converges (reconfigurable
# ~132 s, virtual leader ~157 s); at 160 s the second's virtual leader (~178 s) does not.
DURATIONS_S = {1: 170.0, 2: 160.0}


def tiny(dir_: Path) -> list[Path]:
    paths = []
    for seed, duration in DURATIONS_S.items():
        s = generate(4, 1, seed)
        s = replace(s, meta=replace(s.meta, duration_s=duration))
        p = dir_ / f"tiny{seed}.toml"
        p.write_text(to_toml(s))
        paths.append(p)
    return paths


def p90(values: list[float]) -> float:
    """Linear interpolation between the order statistics at rank 0.9 (n - 1)."""
    v = sorted(values)
    pos = 0.9 * (len(v) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (pos - lo)


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], Path, subprocess.CompletedProcess[str]]:
    d = tmp_path_factory.mktemp("sweep")
    paths = tiny(d)
    out = d / "out"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("COLUMNS", "250")  # (the table's width: each path on one line)
        r = reconswarm("sweep", *map(str, paths), "--seeds", "0:2", "--planner", ",".join(PLANNERS), "--jobs", "2",
                       "-o", str(out), timeout=600)
    return paths, out, r


def read_rows(out: Path) -> tuple[list[str], list[dict[str, str]]]:
    with (out / "results.csv").open(newline="") as f:
        rd = csv.reader(f)
        header = next(rd)
        return header, [dict(zip(header, row, strict=True)) for row in rd]


def test_csv_has_every_run_once_with_the_specified_columns(swept):
    paths, out, r = swept
    assert r.returncode == 0, r.stderr
    header, rows = read_rows(out)
    assert tuple(header) == COLUMNS
    assert len(rows) == len(paths) * len(SEEDS) * len(PLANNERS)
    keys = sorted((row["scenario"], row["planner"], int(row["seed"])) for row in rows)
    assert keys == sorted((str(p), k, s) for p in paths for k in PLANNERS for s in SEEDS)
    # each run left its record where the sweep says
    for row in rows:
        stem = Path(row["scenario"]).stem
        assert (out / "runs" / stem / row["planner"] / f"seed{row['seed']}" / "run.db").is_file()
    converged = {row["converged"] for row in rows}
    assert converged == {"True", "False"}, "the tiny sweep is meant to have both outcomes"
    for row in rows:  # a run without convergence has no convergence time
        assert (row["convergence_time_s"] == "") == (row["converged"] == "False")


@pytest.mark.parametrize("which", [(1, "virtual-leader", 1), (2, "virtual-leader", 0)])
def test_a_row_equals_the_engine_run_directly(swept, tmp_path, which):
    paths, out, _ = swept
    file_seed, kind, seed = which
    path = paths[list(DURATIONS_S).index(file_seed)]
    _, rows = read_rows(out)
    (row,) = [r for r in rows if r["scenario"] == str(path) and r["planner"] == kind and int(r["seed"]) == seed]
    s = load(path).with_planner(kind).with_seed(seed)
    summary = engine.run(engine.SimConfig(s, tmp_path / "direct"))
    for col in COLUMNS:
        if col in ("scenario", "wall_time_s"):
            continue
        want = path_length_mean_m(summary) if col == "path_length_mean_m" else summary[col]
        assert row[col] == ("" if want is None else str(want)), col
    assert float(row["wall_time_s"]) > 0


def test_table_per_scenario_and_planner(swept):
    paths, out, r = swept
    _, rows = read_rows(out)
    table = [[c.strip() for c in re.split(r"[│┃|]", ln) if c.strip()] for ln in r.stdout.splitlines()
             if any(f" {kind} " in ln for kind in PLANNERS)]
    want = []
    for path in paths:
        for kind in PLANNERS:
            mine = [x for x in rows if x["planner"] == kind and x["scenario"] == str(path)]
            times = [float(x["convergence_time_s"]) for x in mine if x["converged"] == "True"]
            contacts = sum(int(x["collisions"]) for x in mine)
            want.append([str(path), kind, str(len(mine)), f"{len(times)} ({100.0 * len(times) / len(mine):.0f} %)",
                         f"{statistics.median(times):.2f}" if times else "-", f"{p90(times):.2f}" if times else "-",
                         str(contacts)])
    assert table == want


def test_seeds_that_changed_nothing_are_said_in_one_line_per_scenario(swept):
    """Where a scenario's seeds all gave the same row (no agent stalled), the sweep says so, not more."""
    paths, out, r = swept
    _, rows = read_rows(out)
    same = {}
    for path in paths:
        kinds = [k for k in PLANNERS if len({tuple(v for c, v in x.items() if c not in ("seed", "wall_time_s"))
                                             for x in rows if x["scenario"] == str(path) and x["planner"] == k}) == 1]
        if kinds:
            same[str(path)] = kinds
    assert same, "the tiny sweep is meant to have seeds that change nothing"
    notes = [ln for ln in r.stderr.splitlines() if "the seed drives only the deadlock perturbation" in ln]
    assert [n.split(": ")[1] for n in notes] == list(same)
    for note, kinds in zip(notes, same.values(), strict=True):
        assert f"gave one and the same row ({', '.join(kinds)})" in note


def test_json_prints_rows_and_stats(tmp_path):
    (path, _) = tiny(tmp_path)
    out = tmp_path / "out"
    r = reconswarm("sweep", str(path), "--planner", "reconfigurable", "-o", str(out), "--json", "--jobs", "1")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    (row,) = doc["rows"]
    assert tuple(row) == COLUMNS
    assert row["seed"] == load(path).meta.seed  # default: the file's own seed
    _, csv_rows = read_rows(out)
    assert csv_rows[0]["convergence_time_s"] == str(row["convergence_time_s"])
    assert doc["table"] == [{
        "scenario": str(path), "planner": "reconfigurable", "runs": 1, "converged": 1,
        "convergence_median_s": row["convergence_time_s"], "convergence_p90_s": row["convergence_time_s"],
        "contacts": row["collisions"]}]


def test_run_sweep_takes_any_executor(swept, tmp_path):
    """The same jobs on threads instead of processes: the same rows (but for wall time), in job order."""
    paths, out, _ = swept
    jobs = make_jobs(paths[:1], range(0, 1), PLANNERS, tmp_path)
    seen: list[Any] = []
    with ThreadPoolExecutor(2) as pool:
        rows = run_sweep(jobs, pool, lambda job, row: seen.append(job))
    assert sorted(map(id, seen)) == sorted(map(id, jobs))
    assert [(r["planner"], r["seed"]) for r in rows] == [(k, 0) for k in PLANNERS]
    _, ref = read_rows(out)
    for row in rows:
        (want,) = [x for x in ref if x["scenario"] == row["scenario"] and x["planner"] == row["planner"]
                   and int(x["seed"]) == 0]
        for col in COLUMNS[3:-1]:
            assert ("" if row[col] is None else str(row[col])) == want[col], col


@pytest.mark.parametrize("args, field", [
    (["missing.toml"], "missing.toml"),
    (["{ok}", "--seeds", "5:5"], "--seeds"),
    (["{ok}", "--seeds", "-1:3"], "--seeds"),
    (["{ok}", "--seeds", "x"], "--seeds"),
    (["{ok}", "--planner", "reconfigurable,nope"], "--planner"),
    (["{ok}", "--jobs", "0"], "--jobs"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, field):
    ok = tiny(tmp_path)[0]
    argv = ["sweep", *[a.replace("{ok}", str(ok)) for a in args], "-o", str(tmp_path / "out")]
    if args[0] == "missing.toml":
        argv[1] = str(tmp_path / "missing.toml")
    r = CliRunner().invoke(app, argv)
    assert r.exit_code == 2
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and field in lines[0] and "Traceback" not in r.output
    assert not (tmp_path / "out" / "results.csv").exists()


def test_clashing_stems_keep_every_record(tmp_path):
    """a/x.toml, b/x.toml, c/x-2.toml: six runs, six rows, six records, no two runs in one directory."""
    paths = []
    for n, sub in enumerate(("a", "b", "c")):
        s = generate(3, 1, n + 1)
        s = replace(s, meta=replace(s.meta, duration_s=20.0, seed=0))  # one seed: one record name in each
        (tmp_path / sub).mkdir()
        paths.append(tmp_path / sub / ("x-2.toml" if sub == "c" else "x.toml"))
        paths[-1].write_text(to_toml(s))
    out = tmp_path / "out"
    r = reconswarm("sweep", *map(str, paths), "--planner", ",".join(PLANNERS), "--jobs", "2", "-o", str(out),
                   timeout=300)
    assert r.returncode == 0, r.stderr
    _, rows = read_rows(out)
    assert len(rows) == 6
    records = sorted((out / "runs").glob("*/*/seed*/run.db"))
    assert len(records) == 6
    assert {p.relative_to(out / "runs").parts[0] for p in records} == {"x", "x-2", "x-3"}
