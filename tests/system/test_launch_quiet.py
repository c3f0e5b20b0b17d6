"""`--no-progress` means no progress output at all (issue 21, friction 7): no bar, and none of the
`t = ... s` lines the launcher logs in place of a bar (it logged the first at once, then every 5 s)."""

from __future__ import annotations

import json
from pathlib import Path

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from tests.support import run_launcher


def test_no_progress_prints_no_t_lines(tmp_path: Path, out: Path) -> None:
    scen = tmp_path / "g.toml"
    scen.write_text(to_toml(generate(3, 1, 1)))
    p = run_launcher(out, "-s", str(scen), "--json")  # (run_launcher passes --no-progress)
    assert p.returncode == 0, p.stderr[-3000:]
    assert json.loads(p.stdout)["converged"]
    assert not [ln for ln in p.stderr.splitlines() if "t = " in ln], p.stderr
