"""`reconswarm sim --record-period S`: fewer tick rows, the same mission outcome in the summary (convergence
time, splits, merges, minimum gaps); a period that is no multiple of dt_s is refused in one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from reconswarm.record.store import RunRecord

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"
SAME = ("convergence_time_s", "final_max_error_m", "min_agent_gap_m", "min_obstacle_gap_m", "splits", "merges",
        "collisions", "safety_violations", "converged")


def sim(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", "sim", str(PAPER), *args],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)


def test_a_decimated_record_keeps_the_missions_outcome(tmp_path):
    full, every = sim("-o", str(tmp_path / "full"), "--json"), sim("-o", str(tmp_path / "dec"), "--json",
                                                                   "--record-period", "1")
    assert full.returncode == 0 and every.returncode == 0, (full.stderr, every.stderr)
    a, b = json.loads(full.stdout), json.loads(every.stdout)
    assert {k: a[k] for k in SAME} == {k: b[k] for k in SAME}
    assert a["convergence_time_s"] == 222.25 and (a["splits"], a["merges"]) == (3, 5)
    with RunRecord(tmp_path / "dec" / "run.db") as rec:
        k = rec.ticks().k
    assert k[0] == 0 and all(int(x) % 20 == 0 for x in k[:-1]) and int(k[-1]) == round(222.25 / 0.05)
    assert (tmp_path / "dec" / "run.db").stat().st_size < (tmp_path / "full" / "run.db").stat().st_size / 5


@pytest.mark.parametrize("period", ["0.07", "0", "-1", "nan"])
def test_a_period_that_is_no_multiple_of_dt_is_refused(tmp_path, period):
    r = sim("-o", str(tmp_path / "run"), "--record-period", period)
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and "--record-period" in lines[0] and "0.05" in lines[0], r.stderr
    assert not (tmp_path / "run" / "run.db").exists()
