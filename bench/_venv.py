"""The project's environment for a benchmark script started by another Python (`bench/bench_paper.py` by its
shebang, or `python3 bench/bench_paper.py`): imported first, it re-runs the script with the project's
.venv/bin/python when this Python lacks the project or its dependencies, and says in one line how to get that
environment when there is none (exit 2)."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
NEEDS = ("numpy", "zenoh", "reconswarm")


def _missing() -> list[str]:
    return [m for m in NEEDS if importlib.util.find_spec(m) is None]


def ensure() -> None:
    missing = _missing()
    if not missing:
        return
    venv_python = ROOT / ".venv" / "bin" / "python"
    here = Path(sys.prefix).resolve() == (ROOT / ".venv").resolve()
    script = sys.argv[0]
    if venv_python.exists() and not here:
        os.execv(str(venv_python), [str(venv_python), script, *sys.argv[1:]])
    sys.stderr.write(f"{Path(script).name}: error: no {', '.join(missing)} in {sys.executable}; set up the project's "
                     f"environment first (deploy/setup_env.sh, sourced by deploy/run_local.sh), then run "
                     f"{ROOT / '.venv' / 'bin' / 'python'} {script}\n")
    raise SystemExit(2)


ensure()
