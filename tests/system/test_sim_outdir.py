"""The quick start's two `sim` commands keep both records (issue 21, friction 8): by default a run goes to
runs/sim/<scenario>-<planner> (with -seed<S> when --seed is given), and `monitor export -o` says what it
wrote."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from tests.support import summary

pytestmark = pytest.mark.parallel  # (no launch, no router, no wall-clock bound: beside the unit tests)


def _cli(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


def test_each_planner_and_seed_keeps_its_own_record(tmp_path: Path) -> None:
    (tmp_path / "g.toml").write_text(to_toml(generate(3, 1, 1)))
    runs = [((), "runs/sim/g-reconfigurable"), (("--planner", "virtual-leader"), "runs/sim/g-virtual-leader"),
            (("--seed", "4"), "runs/sim/g-reconfigurable-seed4")]
    for args, where in runs:
        r = _cli(tmp_path, "sim", "g.toml", *args)
        assert r.returncode == 0, r.stderr
        assert r.stdout.strip().splitlines()[-1] == f"record: {where}/run.db"
    for args, where in runs:
        s = summary(tmp_path / where / "run.db")
        assert s["planner"] == ("virtual-leader" if "virtual-leader" in args else "reconfigurable")
        assert s["seed"] == (4 if "--seed" in args else generate(3, 1, 1).meta.seed)
    r = _cli(tmp_path, "monitor", "export", "runs/sim/g-reconfigurable/run.db", "-o", "t.csv")
    assert r.returncode == 0, r.stderr
    rows = len((tmp_path / "t.csv").read_text().splitlines()) - 1
    assert r.stdout.strip() == f"wrote t.csv: {rows} rows" and rows > 0
