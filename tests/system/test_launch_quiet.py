"""`--no-progress` means no progress output at all (issue 21, friction 7): no bar, and none of the
`t = ... s` lines the launcher logs in place of a bar (it logged the first at once, then every 5 s)."""

from __future__ import annotations

import json
from pathlib import Path

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from tests.support import run_launcher, scenario_with


def test_no_progress_prints_no_t_lines(tmp_path: Path, out: Path) -> None:
    # 10 s of the mission: the launcher logs its first line at the first clock, so a run of any length shows one.
    # (This scenario's launch to convergence: tests/system/test_two_runs.py `small`.)
    scen = scenario_with(tmp_path, "g.toml", to_toml(generate(3, 1, 1)), **{"duration_s = 400.0": "duration_s = 10.0"})
    p = run_launcher(out, "-s", str(scen), "--json")  # (run_launcher passes --no-progress)
    assert p.returncode == 1, p.stderr[-3000:]  # (not converged in 10 s: the documented "mission failed")
    s = json.loads(p.stdout)
    assert not s["converged"] and s["ticks"] == 201 and s["duration_s"] == 10.0, s
    assert not [ln for ln in p.stderr.splitlines() if "t = " in ln], p.stderr
