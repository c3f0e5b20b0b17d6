"""The roles own their commands (issue 19, deliverable 6): agent/cli.py, simworld/cli.py and monitor/cli.py hold
`reconswarm agent`, `reconswarm simworld` and `reconswarm monitor ...`; the top floor only registers them, and
`python -m agent|simworld|monitor` runs the very same commands without importing the top floor."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from reconswarm_bringup.cli import app

ROOT = Path(__file__).resolve().parents[2]
WIDE = {"COLUMNS": "200", "TERMINAL_WIDTH": "200", "NO_COLOR": "1"}
MONITOR = ["summary", "events", "export", "plot", "animate", "record"]


def _role_app(role: str) -> typer.Typer:
    if role == "agent":
        from agent.cli import app as agent_app

        return agent_app
    if role == "simworld":
        from simworld.cli import app as simworld_app

        return simworld_app
    from monitor.cli import monitor_app

    return monitor_app


def _help(the_app: typer.Typer, args: list[str], prog: str) -> str:
    r = CliRunner().invoke(the_app, [*args, "--help"], prog_name=prog, env=WIDE)
    assert r.exit_code == 0, r.output
    return r.output


def _without_usage(text: str) -> str:
    return re.sub(r"Usage: [^\n]*", "Usage:", text)


@pytest.mark.parametrize("cmd", [["agent"], ["simworld"], ["monitor"], *[["monitor", c] for c in MONITOR]],
                         ids=" ".join)
def test_python_m_is_the_same_command(cmd: list[str]) -> None:
    top = _help(app, cmd, "reconswarm")
    own = _help(_role_app(cmd[0]), cmd[1:], f"python -m {cmd[0]}")
    assert f"Usage: reconswarm {' '.join(cmd)} [OPTIONS]" in top
    assert re.search(rf"Usage: python -m {' '.join(cmd)} \[OPTIONS\]", own), own  # (not `python -m agent agent`)
    assert _without_usage(own) == _without_usage(top)


@pytest.mark.parametrize("role", ["agent", "simworld", "monitor"])
def test_a_role_command_does_not_import_the_top_floor(role: str) -> None:
    code = f"import json, sys, {role}.cli, {role}.__main__; print(json.dumps(sorted(sys.modules)))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    loaded = json.loads(r.stdout)
    assert not [m for m in loaded if m.startswith("reconswarm_bringup")], loaded
    others = {"agent", "simworld", "monitor"} - {role}
    assert not [m for m in loaded if m.split(".")[0] in others], loaded


def test_python_m_agent_bad_input_is_one_line_exit_2(tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "agent", "--scenario", str(tmp_path / "missing.toml"), "--id", "1",
                        "--connect", "tcp/127.0.0.1:9"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [f"reconswarm: error: {tmp_path / 'missing.toml'}: file not found"]
