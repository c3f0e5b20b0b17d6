"""Helpers for tests that run the distributed deployment with real processes on 127.0.0.1."""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from reconswarm.geometry.plane import Edges
from reconswarm.net import wire
from reconswarm.net.node import Role, Token
from reconswarm.paper.knowledge import obstacle_view
from reconswarm.paper.planner import ObstacleView

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def launcher_cmd(out: Path, *args: str, port: int | None = None) -> list[str]:
    port = port or free_port()
    return [sys.executable, "-m", "reconswarm_bringup.cli_launch", "--router", f"tcp/127.0.0.1:{port}", "-o", str(out),
            "--no-progress", *args]


def run_launcher(out: Path, *args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run(launcher_cmd(out, *args), capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def reconswarm(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def summary(db: Path) -> dict:
    p = reconswarm("monitor", "summary", str(db), "--json")
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def events(db: Path) -> list[dict]:
    p = reconswarm("monitor", "events", str(db), "--json")
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def trajectories(db: Path) -> dict[tuple[float, int], tuple[float, float, float]]:
    p = reconswarm("monitor", "export", str(db), "--format", "csv")
    assert p.returncode == 0, p.stderr
    rows = csv.DictReader(io.StringIO(p.stdout))
    return {(round(float(r["t_s"]), 6), int(r["agent"])): (float(r["px_m"]), float(r["py_m"]), float(r["theta_rad"]))
            for r in rows}


def max_difference(a: dict, b: dict) -> float:
    assert a.keys() == b.keys(), f"different ticks/agents: {len(a)} vs {len(b)} rows"
    return float(max(np.abs(np.array(a[k]) - np.array(b[k])).max() for k in a))


def pids(out: Path) -> list[int]:
    tsv = out / "processes.tsv"
    if not tsv.exists():
        return []
    return [int(line.split("\t")[2]) for line in tsv.read_text().splitlines() if line.count("\t") == 2]


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is dead for our purposes
        state = Path(f"/proc/{pid}/stat").read_text().split()[2]
        return state != "Z"
    except OSError:
        return False


def assert_all_gone(out: Path, grace_s: float = 5.0) -> None:
    """Every process the run started has exited; kill (and fail on) any leftover, by PID."""
    deadline = time.monotonic() + grace_s
    left = [p for p in pids(out) if alive(p)]
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = [p for p in left if alive(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert not left, f"processes outlived the run: {left}"


def scenario_with(tmp: Path, name: str, text: str, **replace: str) -> Path:
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new, 1)
    path = tmp / name
    path.write_text(text)
    return path


def faults_log(out: Path) -> list[tuple[float, float, str]]:
    """(wall unix time, simulated time, description) of each fault the launcher injected."""
    rows = []
    for line in (out / "faults.tsv").read_text().splitlines():
        wall, t, what = line.split("\t")
        rows.append((float(wall), float(t), what))
    return rows


def positions(db: Path, agent: int) -> list[tuple[float, float, float]]:
    """(t, px, py) of one agent over the run."""
    traj = trajectories(db)
    return sorted((t, xy[0], xy[1]) for (t, a), xy in traj.items() if a == agent)


def paper_with(tmp: Path, **replace: str) -> Path:
    return scenario_with(tmp, "paper.toml", PAPER.read_text(), **replace)


def tick_count(db: Path) -> int:
    """Ticks recorded so far in a run record that may still be written (0 if not readable yet)."""
    import sqlite3

    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as c:
            return int(c.execute("SELECT COUNT(*) FROM ticks").fetchone()[0])
    except sqlite3.Error:
        return 0


def wait_for_ticks(db: Path, n: int, launch: subprocess.Popen[Any] | None, timeout_s: float,
                   why: Callable[[], str] | str = "") -> None:
    """Wait until the run record at db holds n ticks; fail the test if the launch exits first or timeout_s
    passes (the message: `why`, e.g. the launch's stderr so far)."""
    deadline = time.monotonic() + timeout_s
    while tick_count(db) < n:
        if (launch is not None and launch.poll() is not None) or time.monotonic() > deadline:
            raise AssertionError((why() if callable(why) else why) or f"the run did not record {n} ticks in {db}")
        time.sleep(0.2)


def restart_and_rejoin(out: Path, agent: int, at_s: float, after_s: float) -> list[str]:
    """Run the paper mission with `agent` restarted at `at_s` (`after_s` wall seconds later); check the mission
    completed without contact or loss and that the agent was lost and joined again. Returns the agent's
    "joining at tick" log lines (which name the obstacle sets it got from its peers' caches)."""
    p = run_launcher(out, "--fault", f"restart:agent:{agent}@{at_s:g}+{after_s:g}", "--json")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads(p.stdout)
    assert s["converged"] and s["collisions"] == 0 and s["agents_lost"] == []
    ev = [e["kind"] for e in events(out / "run.db") if e.get("agent") == agent]
    assert ev == ["agent_lost", "agent_joined"]
    log = (out / "logs" / f"agent-{agent}.log").read_text().splitlines()
    return [ln for ln in log if "joining at tick" in ln]


def view_of(p: np.ndarray, n_rows: int, n_cols: int, entries: list[tuple[int, int, np.ndarray]]) -> ObstacleView:
    """obstacle_view from (row, column, hull) entries."""
    rows = np.array([e[0] for e in entries], dtype=np.int64)
    cols = np.array([e[1] for e in entries], dtype=np.int64)
    return obstacle_view(p, n_rows, n_cols, rows, cols, Edges.of([e[2] for e in entries]))


def read_run_id(out: Path) -> str:
    """The run id a launch wrote to OUTDIR/run_id (its keys are `swarm/<run id>/...`)."""
    return (out / "run_id").read_text().strip()


def run_keys(out: Path) -> str:
    """`swarm/<run id>` of a launch."""
    return f"swarm/{read_run_id(out)}"


def joined(agent: int) -> Token:
    """Agent `agent`'s liveliness token appeared (a node input)."""
    return Token(Role.AGENT, True, agent)


def left(agent: int) -> Token:
    """Agent `agent`'s liveliness token went away."""
    return Token(Role.AGENT, False, agent)


def world_token(up: bool) -> Token:
    """The world's liveliness token appeared (up) or went away."""
    return Token(Role.WORLD, up)


def beacon(aid: int, k: int, px: float, py: float, radius_m: float = 2.0, dt_s: float = 0.05) -> wire.Beacon:
    """Agent `aid`'s beacon of tick k at head point (px, py) (the paper's dt unless told)."""
    return wire.Beacon(aid, k, k * dt_s, px, py, radius_m)
