"""An agent process that refuses its input at start (exit 2) ends the launch at once, with one line naming it and
exit 3 (a process of the run could not start), instead of waiting out the world's start timeout for an agent
that will never come (issue 51, item 8). The launcher's supervision loop with a real agent process given an
id it refuses, beside a world and a monitor that would wait."""

from __future__ import annotations

import logging
import subprocess
import sys
import time
from pathlib import Path

import pytest

from reconswarm.scenario.model import load
from reconswarm_bringup import launcher
from reconswarm_bringup.config import LaunchConfig
from reconswarm_bringup.fleet import Fleet, Proc
from tests.support import PAPER

WORLD_WAITS_S = 60.0  # the stand-in world's start timeout: the launch must end well before it


class NotStarted:
    """The clock as the launcher sees it before the world's first tick."""

    t, k, alive, end = 0.0, -1, 0, None

    def poll(self) -> None:
        pass


def _waiting(fleet: Fleet, role: str, out: Path) -> Proc:
    popen = subprocess.Popen([sys.executable, "-c", f"import time; time.sleep({WORLD_WAITS_S})"])
    proc = Proc(role, "-", [], popen, out / f"{role}.log")
    fleet.procs.append(proc)
    return proc


def test_an_agent_that_exits_2_at_start_ends_the_launch_at_once(tmp_path: Path,
                                                                 caplog: pytest.LogCaptureFixture) -> None:
    fleet = Fleet(tmp_path, {})
    world, mon = _waiting(fleet, "simworld", tmp_path), _waiting(fleet, "monitor", tmp_path)
    fleet.start("agent", "1-5", ["agent", "--scenario", str(PAPER), "--ids", "1-²"], members=tuple("12345"))
    t0 = time.monotonic()
    try:
        with caplog.at_level(logging.INFO, logger="reconswarm.launch"):
            code = launcher._supervise(LaunchConfig(out=tmp_path, progress=False), load(PAPER), fleet, world, mon,
                                       NotStarted(), [], [])  # type: ignore[arg-type]
    finally:
        fleet.stop_all()
    took = time.monotonic() - t0
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert code == 3 and took < WORLD_WAITS_S / 2, (code, took, errors)
    assert any(e.startswith("agent 1-5 could not start (exit 2: ") and "--ids: " in e for e in errors), errors
    assert world.popen.poll() is not None and mon.popen.poll() is not None  # stopped with the run
