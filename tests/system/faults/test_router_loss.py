"""The router SIGKILLed by its pid mid-run (realtime): the launcher starts it again on the same endpoint,
every client reconnects by itself, and the record blames no agent for it (issue 22, case 3)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
from pathlib import Path

import pytest

from tests.support import PAPER, ROOT, events, launcher_cmd, scenario_with, wait_clock_at

pytestmark = pytest.mark.realtime  # (holds only if the machine keeps the clock's pace: run alone, last)


def three_agents(tmp: Path) -> Path:
    """The paper's first three agents, no obstacle (as tests/system/test_deploy.py's realtime run)."""
    text = PAPER.read_text().split("[[agents]]")[0] + "".join(
        "[[agents]]" + part for part in PAPER.read_text().split("[[agents]]")[1:4])
    return scenario_with(tmp, "rt3.toml", text.split("[[obstacles]]")[0], **{'name = "paper"': 'name = "rt3"'})


def routers(out: Path) -> list[int]:
    rows = [line.split("\t") for line in (out / "processes.tsv").read_text().splitlines()]
    return [int(r[2]) for r in rows if r[0] == "router"]


def test_router_killed_mid_run_is_restarted_and_no_agent_is_lost(tmp_path: Path, out: Path) -> None:
    cmd = launcher_cmd(out, "-s", str(three_agents(tmp_path)), "--clock", "realtime", "--speed", "4", "--json")
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_clock_at(out / "run.db", 10.0, proc, 60)  # well under way
        (first,) = routers(out)
        os.kill(first, signal.SIGKILL)  # from outside, as a user's `kill -9 PID`
        stdout, stderr = proc.communicate(timeout=150)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            proc.communicate(timeout=30)
    assert len(routers(out)) == 2 and routers(out)[0] == first  # started again, once
    assert "router died (exit -9)" in stderr and "restarting it on the same endpoint" in stderr, stderr[-3000:]
    s = json.loads(stdout)
    assert s["agents_lost"] == [], stderr[-3000:]
    assert [e for e in events(out / "run.db") if e["kind"] == "agent_lost"] == []
    assert proc.returncode == 0 and s["converged"] and s["collisions"] == 0, stderr[-3000:]
    for role in ("simworld", "monitor"):  # each saw its own link go and come back
        log = (out / "logs" / f"{role}.log").read_text()
        assert "the router is gone (our own session's link)" in log and "connected to a router again" in log
