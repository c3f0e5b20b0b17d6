"""Every benchmark script runs as docs/benchmarks.md says (issue 52, friction 7): `bench/bench_paper.py` by itself (a
shebang, the executable bit in git, the project's .venv found even from another Python) and `--help` lists its
options. bench/'s helper modules (imported by the scripts, no main) are not scripts."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from tests.support import ROOT

BENCH = ROOT / "bench"
SCRIPTS = sorted(p for p in BENCH.glob("*.py") if 'if __name__ == "__main__":' in p.read_text())


def test_the_scripts_are_found() -> None:
    names = {p.name for p in SCRIPTS}
    assert {"bench_paper.py", "baseline_numpy.py", "bench_deploy.py", "floor.py"} <= names
    assert not names & {"_common.py", "_venv.py", "grid.py", "floor_pattern.py"}


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_each_script_runs_by_itself_and_lists_its_options(script: Path) -> None:
    assert script.read_text().startswith("#!/usr/bin/env python3\n")
    mode = subprocess.run(["git", "ls-files", "-s", str(script.relative_to(ROOT))], cwd=ROOT, capture_output=True,
                          text=True, check=True).stdout.split(" ")[0]
    assert mode == "100755", f"{script.name}: git mode {mode!r} (git update-index --chmod=+x)"
    # started by its shebang from another directory, with the system's Python first on PATH
    env = dict(os.environ, PYTHONPATH=str(ROOT), PATH=f"/usr/bin:/bin:{os.environ.get('PATH', '')}")
    r = subprocess.run([str(script), "--help"], cwd="/", capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("usage: ") and "--help" in r.stdout and "Traceback" not in r.stderr, r.stdout
