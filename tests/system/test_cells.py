"""Neighbourhood-scoped keys with real processes: a sparse 36-agent grid in lockstep equals the in-process
engine to 0.0 m, stays deterministic, and an agent at the grid's corner does not receive every beacon."""

from __future__ import annotations

import ast
import importlib.util
import json
import re
from pathlib import Path

from reconswarm.scenario.model import to_toml
from tests.support import ROOT, max_difference, reconswarm, run_launcher, trajectories

N = 36  # a 6 x 6 grid 25 m apart (bench/grid.py): 125 m across, wider than what one agent listens to


def _grid_toml(path: Path, n: int, duration_s: float) -> Path:
    spec = importlib.util.spec_from_file_location("bench_grid", ROOT / "bench" / "grid.py")
    assert spec is not None and spec.loader is not None
    grid = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(grid)
    path.write_text(to_toml(grid.grid_scenario(n, duration_s)))
    return path


def _samples_per_tick(log: Path, ticks: int) -> float:
    text = log.read_text(errors="replace")
    start = ast.literal_eval(re.findall(r"usage at start: (\{.*\})", text)[-1])
    end = ast.literal_eval(re.findall(r"usage: (\{.*\})", text)[-1])
    return float((end["msgs_in"] - start["msgs_in"]) / ticks)


def test_sparse_grid_lockstep_equals_inprocess_engine(tmp_path: Path, out: Path) -> None:
    scen = _grid_toml(tmp_path / "grid36.toml", N, 6.0)
    p = run_launcher(out, "-s", str(scen), "--json", timeout=900)
    assert p.returncode in (0, 1), p.stderr[-3000:]  # 1: not converged in 6 s, the documented "mission failed"
    dist = json.loads(p.stdout)
    ticks = round(6.0 / 0.05) + 1
    assert dist["mode"] == "lockstep" and dist["ticks"] == ticks and dist["collisions"] == 0
    # No agent acted without a tick's data, and no peer showed up within reach unexpected (the speed bound).
    assert dist["deterministic"] is True and dist["determinism_lost_at_s"] is None
    sim = reconswarm("sim", str(scen), "-o", str(tmp_path / "sim"), "--json")
    assert sim.returncode in (0, 1), sim.stderr
    got, ref = trajectories(out / "run.db"), trajectories(tmp_path / "sim" / "run.db")
    assert len(got) == ticks * N
    assert max_difference(got, ref) == 0.0
    # The corner agent (id 1 at the origin) listens to the cells within reach + 3 V dt of it: not to the far
    # column and row of the grid, so it receives fewer samples a tick than the N - 1 beacons of all-to-all.
    corner = _samples_per_tick(out / "logs" / "agent-1.log", ticks - 1)
    assert corner < N - 1 - 5, corner
