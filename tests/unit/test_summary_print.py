"""How a summary reads (issue 21, friction 8): counts are whole numbers, a realtime run claims no
determinism (so it shows neither `deterministic: no` nor `determinism_lost_at_s: None`), and a sweep's
progress calls a run that did not converge what it is, not FAILED."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console

from reconswarm.record.store import RunRecord, RunWriter
from reconswarm.record.summary import render, summarize
from reconswarm.scenario.generate import generate
from reconswarm_bringup.cli_sweep import outcome


def _record(tmp_path: Path, mode: str, extra: dict) -> dict:
    s = generate(3, 1, 1)
    w = RunWriter(tmp_path / "run.db", s, mode)
    n = len(s.agents)
    w.tick(0, 0.0, s.starts.copy(), s.headings.copy(), np.ones(n, dtype=bool), 50.0, 5.0, 5.0, 1)
    w.close(wall_time_s="1.0", finished="1", extra=extra)
    rec = RunRecord(tmp_path / "run.db")
    try:
        return summarize(rec)
    finally:
        rec.close()


def _text(summary: dict) -> str:
    con = Console(width=200, record=True, color_system=None)
    con.print(render(summary))
    return con.export_text()


def test_realtime_counts_are_whole_and_determinism_is_not_claimed(tmp_path: Path) -> None:
    s = _record(tmp_path, "realtime", {"missed_deadlines": 62.0, "deadlines": 4446.0, "world_overruns": 3.0,
                                       "latency_samples": 4000.0, "missed_deadline_ratio": 0.01395,
                                       "latency_p50_ms": 2.0, "deterministic": False,
                                       "determinism_lost_at_s": None})
    assert s["missed_deadlines"] == 62 and isinstance(s["missed_deadlines"], int)
    assert isinstance(s["deadlines"], int) and isinstance(s["world_overruns"], int)
    assert s["latency_p50_ms"] == 2.0 and isinstance(s["latency_p50_ms"], float)  # a measure stays a float
    text = _text(s)
    lines = {ln.split("│")[1].strip(): ln.split("│")[2].strip() for ln in text.splitlines() if ln.count("│") >= 3}
    assert lines["missed_deadlines"] == "62" and lines["deadlines"] == "4446"
    assert lines["deterministic"].startswith("not claimed")
    assert "determinism_lost_at_s" not in lines


def test_lockstep_that_lost_determinism_says_when(tmp_path: Path) -> None:
    s = _record(tmp_path, "lockstep", {"deterministic": False, "determinism_lost_at_s": 30.3})
    text = _text(s)
    lines = {ln.split("│")[1].strip(): ln.split("│")[2].strip() for ln in text.splitlines() if ln.count("│") >= 3}
    assert lines["deterministic"] == "no" and lines["determinism_lost_at_s"] == "30.3"


def test_sweep_progress_names_outcomes() -> None:
    assert outcome({"converged": False, "collisions": 0}) == "not converged"
    assert outcome({"converged": True, "collisions": 0}) == "converged"
    assert outcome({"converged": True, "collisions": 2}) == "2 collision(s)"
