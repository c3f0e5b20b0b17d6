"""A navground planner in the distributed lockstep run: each agent process plans with its own behaviour, and
the trajectories equal the in-process engine's bit for bit (navground's behaviours are deterministic, and each
is given the same neighbours, hulls and target in the same order as the engine gives them)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.support import PAPER, max_difference, reconswarm, run_launcher, scenario_with, trajectories

pytest.importorskip("navground.core", reason="the navground extra: pip install 'reconswarm[navground]'")


def test_orca_lockstep_equals_inprocess_engine(tmp_path: Path, out: Path) -> None:
    # 40 s of the paper's mission: the swarm reaches the first obstacle and senses and shares it
    scen = scenario_with(tmp_path, "short.toml", PAPER.read_text(),
                         **{"duration_s = 300.0": "duration_s = 40.0", 'kind = "reconfigurable"': 'kind = "orca"'})
    sim = reconswarm("sim", str(scen), "-o", str(tmp_path / "sim"), "--json")
    assert sim.returncode == 1, sim.stderr  # not converged in 40 s
    ref = trajectories(tmp_path / "sim" / "run.db")
    assert json.loads(sim.stdout)["planner"] == "orca"
    p = run_launcher(out, "-s", str(scen), "--json")
    assert p.returncode == 1, p.stderr[-2000:]
    s = json.loads(p.stdout)
    assert s["planner"] == "orca" and s["ticks"] == 801 and s["deterministic"] is True
    got = trajectories(out / "run.db")
    assert len(got) == 801 * 10 and max_difference(got, ref) == 0.0
