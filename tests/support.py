"""Helpers for tests that run the distributed deployment with real processes on 127.0.0.1."""

from __future__ import annotations

import contextlib
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
import zenoh

from reconswarm.geometry.plane import Edges
from reconswarm.net.node import Role, Token
from reconswarm.net.wire import wire
from reconswarm.paper.knowledge import obstacle_view
from reconswarm.paper.planner import ObstacleView

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"


PORTS_ENV = "RECONSWARM_TEST_PORTS"  # "A-B": the tests' ports come from A..B (deploy/run_tests.sh --ports A-B)
_next_port: list[int] = []  # (the next candidate in this process's share of the range)


def port_range(spec: str | None = None, worker: str | None = None, workers: int | None = None) -> range | None:
    """This process's share of RECONSWARM_TEST_PORTS ("A-B", inclusive), or None when it is not set. Under
    pytest-xdist each worker (PYTEST_XDIST_WORKER gwN of PYTEST_XDIST_WORKER_COUNT) draws from a slice of its own,
    so parallel tests never pick the same port."""
    spec = os.environ.get(PORTS_ENV, "") if spec is None else spec
    if not spec.strip():
        return None
    lo_s, sep, hi_s = spec.strip().partition("-")
    if not (sep and lo_s.isdigit() and hi_s.isdigit() and 1024 <= int(lo_s) <= int(hi_s) <= 65535):
        raise ValueError(f"{PORTS_ENV}={spec!r}: expected A-B with 1024 <= A <= B <= 65535")
    lo, hi = int(lo_s), int(hi_s) + 1
    worker = os.environ.get("PYTEST_XDIST_WORKER", "") if worker is None else worker
    n = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) if workers is None else workers
    if worker.startswith("gw") and worker[2:].isdigit() and n > 1:
        share = (hi - lo) // n
        if share < 1:
            raise ValueError(f"{PORTS_ENV}={spec!r}: fewer ports than the {n} test workers")
        i = int(worker[2:]) % n
        lo, hi = lo + i * share, lo + (i + 1) * share
    return range(lo, hi)


def free_port() -> int:
    """A TCP port free on 127.0.0.1: the next free one of RECONSWARM_TEST_PORTS when that is set (in turn, so two
    calls do not return the same port before it is taken), else one of the system's choosing."""
    ports = port_range()
    if ports is None:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            return int(s.getsockname()[1])
    if not _next_port:
        _next_port.append(ports.start + os.getpid() % len(ports))  # (another process on the same range: elsewhere)
    for _ in range(len(ports)):
        port = ports.start + (_next_port[0] - ports.start) % len(ports)
        _next_port[0] = port + 1
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise AssertionError(f"{PORTS_ENV}: no free port in {ports.start}-{ports.stop - 1}")


def wait_until(pred: Callable[[], Any], timeout_s: float, what: str, every_s: float = 0.05,
               proc: subprocess.Popen[Any] | None = None) -> Any:
    """Poll pred until it returns a true value, and return that value; fail naming `what` once timeout_s has
    passed (or once `proc`, the process it waits on, has exited). The one wait for a condition in the tests."""
    deadline = time.monotonic() + timeout_s
    while True:
        got = pred()
        if got:
            return got
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"{what}: the process exited ({proc.returncode}) first")
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not within {timeout_s:g} s")
        time.sleep(every_s)


def attempt(call: Callable[..., Any], *args: Any) -> Any:
    """call(*args), or None if it raised (for wait_until: retry until it succeeds, e.g. opening a session)."""
    try:
        return call(*args)
    except Exception:
        return None


def router_listening(port: int, host: str = "127.0.0.1") -> bool:
    """A TCP connection to host:port succeeds (a router there accepts clients)."""
    try:
        with socket.create_connection((host, port), timeout=1.0):
            return True
    except OSError:
        return False


def wait_router_listening(port: int, timeout_s: float = 60.0, proc: subprocess.Popen[Any] | None = None) -> None:
    """Wait until a router listens on 127.0.0.1:port (`proc`: the router's process, if the test started it)."""
    wait_until(lambda: router_listening(port), timeout_s, f"a router listening on 127.0.0.1:{port}", proc=proc)


def wait_subscribed(session: Any, key: str, timeout_s: float = 10.0, matched: bool = True) -> None:
    """Wait until `session` knows a subscriber of another session to `key` (zenoh's matching status of a publisher
    declared for the wait): a put from `session` on `key` then reaches it. matched=False: until it knows none."""
    pub = session.declare_publisher(key, allowed_destination=zenoh.Locality.REMOTE)
    try:
        wait_until(lambda: pub.matching_status.matching == matched, timeout_s,
                   f"a subscriber to {key} {'known' if matched else 'gone'} to the session")
    finally:
        pub.undeclare()


def wait_token(session: Any, key: str, timeout_s: float = 10.0) -> None:
    """Wait until `session` sees a liveliness token on `key` (declared by another session)."""
    wait_until(lambda: any(r.ok is not None for r in session.liveliness().get(key, timeout=1.0)), timeout_s,
               f"the token {key} seen")


def wait_clock_at(db: Path, t_s: float, launch: subprocess.Popen[Any] | None, timeout_s: float,
                  dt_s: float = 0.05) -> None:
    """Wait until the run recorded at db has reached simulated time t_s (its tick at t_s is recorded)."""
    wait_for_ticks(db, round(t_s / dt_s) + 1, launch, timeout_s, f"the run at {db} never reached t = {t_s:g} s")


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


def gone_within(procs: list[int], timeout_s: float) -> list[int]:
    """Wait up to timeout_s for every process of `procs` to exit; those still alive then."""
    with contextlib.suppress(AssertionError):
        wait_until(lambda: not any(alive(p) for p in procs), timeout_s, "the processes exit", every_s=0.1)
    return [p for p in procs if alive(p)]


def assert_all_gone(out: Path, grace_s: float = 5.0) -> None:
    """Every process the run started has exited; kill (and fail on) any leftover, by PID."""
    left = gone_within(pids(out), grace_s)
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert not left, f"processes outlived the run: {left}"


def end_launch(proc: subprocess.Popen[Any], out: Path, *sessions: Any) -> None:
    """A launch's test is over (passed or not): close its outside sessions (None: never opened), kill the launcher
    if it still runs, and check that every process the run started has exited."""
    for z in sessions:
        if z is not None:
            z.close()
    if proc.poll() is None:
        proc.kill()
        proc.wait()
    assert_all_gone(out)


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


SHORT_TARGET = {"center_m = [800.0, 0.0]": "center_m = [420.0, 0.0]"}


def short_paper(tmp: Path, **replace: str) -> Path:
    """The paper with its target at (420, 0) instead of (800, 0): the same starts, radii, gains and obstacles,
    the same 3 splits and 5 merges around them, converged at 156.3 s instead of 222.25 s (`reconswarm sim`).
    For the fault tests whose point is a fault's harm by the mission's end, not the paper's figures: 30 % less
    of the lockstep wall time they spend. What must be the paper (bit for bit in a mode) runs PAPER itself."""
    return scenario_with(tmp, "paper-short.toml", PAPER.read_text(), **SHORT_TARGET, **replace)


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
    try:
        wait_until(lambda: tick_count(db) >= n, timeout_s, f"{n} ticks in {db}", every_s=0.2, proc=launch)
    except AssertionError as e:
        raise AssertionError((why() if callable(why) else why) or f"the run did not record {n} ticks in {db}: {e}") \
            from None


def restart_and_rejoin(out: Path, restarts: dict[int, tuple[float, float]], *args: str) -> dict[int, list[str]]:
    """Run the mission (launcher ARGS; the paper by default) with each agent of `restarts` restarted at its `at_s`
    (`after_s` wall seconds later); check the mission completed without contact or loss and that each was lost and
    joined again. Returns each agent's "joining at tick" log lines (which name the obstacle sets it got from its
    peers' caches)."""
    faults = [arg for a, (at_s, after_s) in restarts.items()
              for arg in ("--fault", f"restart:agent:{a}@{at_s:g}+{after_s:g}")]
    p = run_launcher(out, *args, *faults, "--json")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads(p.stdout)
    assert s["converged"] and s["collisions"] == 0 and s["agents_lost"] == []
    joined = {}
    for agent in restarts:
        ev = [e["kind"] for e in events(out / "run.db") if e.get("agent") == agent]
        assert ev == ["agent_lost", "agent_joined"], (agent, ev)
        log = (out / "logs" / f"agent-{agent}.log").read_text().splitlines()
        joined[agent] = [ln for ln in log if "joining at tick" in ln]
    return joined


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
