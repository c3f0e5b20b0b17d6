"""The floor of the distributed lockstep tick: its message pattern with nothing of ours behind it.

A router, one world process and N agent processes, each a zenoh client session connected to the router
(the launcher's ZENOH_RUNTIME in the non-router processes, BLOCK congestion control, samples through
reconswarm.net.inbox.Inbox with the same wake-ups), with msgpack payloads of the real messages' shapes
and sizes; no planning, no admission, no record, no monitor. The robots stay at the grid scenario's
starts (bench/grid.py). Per tick:

- the world puts the clock (k, t, alive list) on `swarm/<run>/clock` and each agent's state on
  `swarm/<run>/agent/<id>/state`, then waits for every agent's command of the tick;
- an agent, on its state, puts its beacon and waits for the clock and the beacons it hears, then puts its
  command (k, v_mps, omega_radps) on `swarm/<run>/agent/<id>/cmd`. Two patterns:
  `cells`: the beacon under its head point's cell (`swarm/<run>/cell/<cx>_<cy>/agent/<id>/beacon`), heard
  from the cells CellGrid.listen_cells names around it; it waits for every beacon of those cells, as the
  real agent does (its wait set plus the peers it hears anyway, agent/neighbours.py);
  `all`: every beacon to everyone (`swarm/<run>/agent/<id>/beacon`, heard as `swarm/<run>/agent/*/beacon`).

CPU per tick is measured over a window of ticks after a warm-up (start-up does not count): each agent and
the world read their own rusage (CPU, context switches: every thread of the process) at the window's
first and last tick; the router's CPU is read from
/proc/<pid>/stat when the world says it is at those ticks.

    .venv/bin/python bench/floor.py -n 16 36 64 --ticks 200
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import msgpack

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, median
from grid import grid_scenario

from reconswarm.net.cells import CellGrid
from reconswarm.net.inbox import Inbox
from reconswarm.net.keys import Keys
from reconswarm.net.session import ZenohOptions, open_session
from reconswarm.net.wire import VERSION
from reconswarm.scenario.model import Scenario

ROOT = Path(__file__).resolve().parent.parent
PATTERNS = ("cells", "all")
STALL_S = 60.0  # a process that makes no progress this long gives up (exit 1): the run is reported failed
XY = tuple[float, float]


# ------------------------------------------------------------------------------------- the pattern (pure)

def head_points(s: Scenario) -> dict[int, XY]:
    """Each agent's head point at its start (the robots do not move in the floor)."""
    l_m, th = s.head_offsets, s.headings
    return {a.id: (float(a.start_m[0] + l_m[i] * math.cos(th[i])), float(a.start_m[1] + l_m[i] * math.sin(th[i])))
            for i, a in enumerate(s.agents)}


def heard(s: Scenario, agent_id: int, pattern: str) -> tuple[frozenset[int], frozenset[int]]:
    """(peers whose beacons reach the agent, the peers it must wait for): in `cells` those publishing in the
    cells it listens to, and those whose position may matter to it (CellGrid.may_matter); in `all` every peer."""
    pts = head_points(s)
    peers = frozenset(a for a in pts if a != agent_id)
    if pattern == "all":
        return peers, peers
    grid = CellGrid.for_scenario(s)
    own = pts[agent_id]
    cells = grid.listen_cells(*own)
    return (frozenset(a for a in peers if grid.cell_of(*pts[a]) in cells),
            frozenset(a for a in peers if grid.may_matter(own, pts[a])))


def pack(obj: dict[str, Any]) -> bytes:
    return msgpack.packb({"v": VERSION, **obj}, use_bin_type=True)


def state_bytes(aid: int, k: int, t: float, p: XY) -> bytes:
    """Same map as wire.state_to_wire (the body centre half a metre behind the head point)."""
    return pack({"id": aid, "k": k, "t": t, "x": p[0] - 0.5, "y": p[1], "theta": 0.0, "px": p[0], "py": p[1]})


def clock_bytes(k: int, t: float, alive: list[int], end: bool = False) -> bytes:
    return pack({"k": k, "t": t, "alive": alive, "mode": "lockstep", "speed": 0.0, "end": end,
                 "reason": "time limit" if end else "", "rejected": 0, "stats": {}})


def beacon_bytes(aid: int, k: int, t: float, p: XY, radius_m: float) -> bytes:
    return pack({"id": aid, "k": k, "t": t, "px": p[0], "py": p[1], "radius": radius_m, "rev": 0})


def cmd_bytes(aid: int, k: int) -> bytes:
    return pack({"id": aid, "k": k, "v_mps": 0.123456789, "omega_radps": -0.987654321})


# ------------------------------------------------------------------------------------------- processes

def cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def switches() -> int:
    """Context switches of the process so far (voluntary: a thread waited; involuntary: preempted)."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_nvcsw + ru.ru_nivcsw


def session(port: int) -> Any:
    return open_session(ZenohOptions.build([f"tcp/127.0.0.1:{port}"], None, "client", None), "floor", 30.0)


def agent_main(port: int, run: str, n: int, aid: int, pattern: str, start: int, end: int) -> int:
    import zenoh

    s = grid_scenario(n, 10.0)
    keys, p = Keys(run), head_points(s)[aid]
    radius = float(s.radii[s.agent_index(aid)])
    hear, _ = heard(s, aid, pattern)
    z = session(port)
    block, remote = zenoh.CongestionControl.BLOCK, zenoh.Locality.REMOTE
    inbox = Inbox()
    cb = inbox.handler()
    if pattern == "cells":
        grid = CellGrid.for_scenario(s)
        pub_beacon = z.declare_publisher(keys.beacon(grid.cell_of(*p), aid), congestion_control=block)
        subs = [z.declare_subscriber(keys.cell_agents(c, "beacon"), cb, allowed_origin=remote)
                for c in sorted(grid.listen_cells(*p))]
    else:
        pub_beacon = z.declare_publisher(keys.agent(aid, "beacon"), congestion_control=block)
        subs = [z.declare_subscriber(keys.all_agents("beacon"), cb, allowed_origin=remote)]
    pub_cmd = z.declare_publisher(keys.cmd(aid), congestion_control=block)
    subs += [z.declare_subscriber(keys.state(aid), inbox.handler(urgent=True)),
             z.declare_subscriber(keys.clock, cb)]
    token = z.liveliness().declare_token(keys.alive_agent(aid))  # last: we are ready to receive
    states: set[int] = set()
    clocks: set[int] = set()
    beacons: dict[int, int] = {}
    k, sent, marks, done = 0, -1, {}, False
    last = time.monotonic()
    try:
        while not done:
            if time.monotonic() - last > STALL_S:
                raise RuntimeError(f"agent {aid}: stuck at tick {k}")
            want = None if k not in states else max(1, len(hear) - beacons.get(k, 0) + (k not in clocks))
            for key, payload, _kind, _src, _at in inbox.take(want, 1.0):
                m = msgpack.unpackb(payload, raw=False)
                if key.endswith("/beacon"):
                    beacons[m["k"]] = beacons.get(m["k"], 0) + 1
                elif key.endswith("/state"):
                    states.add(m["k"])
                    if m["k"] == start:
                        marks[start] = (cpu_s(), Inbox.samples_in, Inbox.wakeups, switches())
                elif m["end"]:
                    marks[end] = (cpu_s(), Inbox.samples_in, Inbox.wakeups, switches())
                    done = True
                else:
                    clocks.add(m["k"])
            if k in states and sent < k:
                pub_beacon.put(beacon_bytes(aid, k, k * s.meta.dt_s, p, radius))
                sent = k
            if k in states and k in clocks and beacons.get(k, 0) >= len(hear):
                pub_cmd.put(cmd_bytes(aid, k))
                states.discard(k)
                clocks.discard(k)
                beacons.pop(k, None)
                k += 1
                last = time.monotonic()
    finally:
        token.undeclare()
        for sub in subs:
            sub.undeclare()
        z.close()
    (c0, m0, w0, s0), (c1, m1, w1, s1) = marks[start], marks[end]
    ticks = end - start
    print(json.dumps({"cpu_ms": 1000 * (c1 - c0) / ticks, "msgs_in": (m1 - m0) / ticks, "wakeups": (w1 - w0) / ticks,
                      "switches": (s1 - s0) / ticks, "heard": len(hear)}), flush=True)
    return 0


def world_main(port: int, run: str, n: int, start: int, end: int) -> int:
    import zenoh

    s = grid_scenario(n, 10.0)
    keys, pts = Keys(run), head_points(s)
    ids = sorted(pts)
    z = session(port)
    block = zenoh.CongestionControl.BLOCK
    inbox = Inbox()
    pub_clock = z.declare_publisher(keys.clock, congestion_control=block)
    pub_state = {a: z.declare_publisher(keys.state(a), congestion_control=block) for a in ids}
    subs = [z.declare_subscriber(keys.all_agents("cmd"), inbox.handler()),
            z.liveliness().declare_subscriber(keys.alive_all, inbox.handler(), history=True)]
    try:
        up: set[int] = set()
        deadline = time.monotonic() + STALL_S
        while len(up) < n:  # the readiness barrier: every agent's token (declared after its subscribers)
            if time.monotonic() > deadline:
                raise RuntimeError(f"world: only {len(up)} of {n} agents came up")
            for key, _p, kind, _src, _at in inbox.take(n - len(up), 0.5):
                what, aid, _leaf = keys.parse(key)
                if what == "alive" and aid is not None and kind == "PUT":
                    up.add(aid)
        t0, wall0, marks = 0.0, 0.0, {}
        for k in range(end + 1):
            if k in (start, end):
                marks[k] = cpu_s()
                print(f"mark {k}", flush=True)
                if k == start:
                    wall0 = time.monotonic()
                else:
                    t0 = time.monotonic() - wall0
            t = k * s.meta.dt_s
            if k == end:
                pub_clock.put(clock_bytes(k, t, ids, end=True))
                break
            pub_clock.put(clock_bytes(k, t, ids))
            for a in ids:
                pub_state[a].put(state_bytes(a, k, t, pts[a]))
            got: set[int] = set()
            last = time.monotonic()
            while len(got) < n:
                if time.monotonic() - last > STALL_S:
                    raise RuntimeError(f"world: tick {k}: commands from {len(got)} of {n} agents")
                for key, payload, _kind, _src, _at in inbox.take(n - len(got), 1.0):
                    if key.endswith("/cmd"):
                        m = msgpack.unpackb(payload, raw=False)
                        if m["k"] == k:
                            got.add(m["id"])
        time.sleep(0.5)  # let the end clock reach every agent before the session goes
    finally:
        for sub in subs:
            sub.undeclare()
        z.close()
    ticks = end - start
    print(json.dumps({"cpu_ms": 1000 * (marks[end] - marks[start]) / ticks, "wall_s": t0, "ticks": ticks}),
          flush=True)
    return 0


# ----------------------------------------------------------------------------------------------- driver

def proc_cpu_s(pid: int) -> float:
    """user + system CPU seconds of a live process (all its threads), from /proc/<pid>/stat."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    import socket

    with socket.socket() as so:
        so.bind(("127.0.0.1", 0))
        return int(so.getsockname()[1])


def floor_run(n: int, pattern: str, ticks: int = 200, warmup: int = 20, timeout_s: float = 900.0) -> dict[str, float]:
    """One floor run: CPU-ms per tick per role over `ticks` ticks after `warmup`, samples and wake-ups in per
    agent per tick (medians over the agents), ticks per wall second. Every process is ended by its PID."""
    from reconswarm_bringup.fleet import batch_policy
    from reconswarm_bringup.launcher import ZENOH_RUNTIME

    if pattern not in PATTERNS:
        raise ValueError(f"pattern: expected one of {PATTERNS}, got {pattern!r}")
    port, run = free_port(), f"floor{os.getpid()}x{n}{pattern}"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    client_env = dict(env, ZENOH_RUNTIME=ZENOH_RUNTIME)
    me = [sys.executable, str(Path(__file__).resolve())]
    common = ["--port", str(port), "--run", run, "--agents", str(n), "--start", str(warmup),
              "--end", str(warmup + ticks)]
    procs: list[subprocess.Popen] = []

    def spawn(cmd: list[str], **kw: Any) -> subprocess.Popen:
        p = subprocess.Popen(cmd, **kw)
        batch_policy(p.pid)  # the scheduling policy of a lockstep run's processes (reconswarm_bringup/fleet.py)
        return p

    with tempfile.TemporaryDirectory(prefix="floor_") as tmp:
        logs = Path(tmp)
        try:
            router = spawn([sys.executable, "-m", "reconswarm_bringup.cli", "router", "--listen",
                            f"tcp/127.0.0.1:{port}"], env=env, cwd=ROOT, stdout=subprocess.DEVNULL,
                           stderr=(logs / "router.log").open("w"))
            procs.append(router)
            agents: list[subprocess.Popen] = []
            for a in range(1, n + 1):
                out = (logs / f"agent{a}.out").open("w")
                agents.append(spawn([*me, "agent", "--id", str(a), "--pattern", pattern, *common],
                                    env=client_env, cwd=ROOT, stdout=out, stderr=(logs / f"agent{a}.log").open("w")))
            procs.extend(agents)
            world = spawn([*me, "world", *common], env=client_env, cwd=ROOT, stdout=subprocess.PIPE,
                          stderr=(logs / "world.log").open("w"), text=True)
            procs.append(world)
            assert world.stdout is not None
            router_cpu = []
            for line in world.stdout:
                if line.startswith("mark"):
                    router_cpu.append(proc_cpu_s(router.pid))
                else:
                    w = json.loads(line)
            deadline = time.monotonic() + timeout_s
            for p in [world, *agents]:
                p.wait(max(1.0, deadline - time.monotonic()))
            failed = [p for p in [world, *agents] if p.returncode != 0]
            if failed or len(router_cpu) != 2:
                err = (logs / ("world.log" if world in failed else "agent1.log")).read_text()[-1500:]
                raise RuntimeError(f"floor run N={n} {pattern}: {len(failed)} processes failed: {err}")
            res = [json.loads((logs / f"agent{a}.out").read_text()) for a in range(1, n + 1)]
        finally:
            for p in reversed(procs):
                if p.poll() is None:
                    p.terminate()
            for p in procs:
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
    def med(key: str) -> float:
        return median([r[key] for r in res])

    return {"n": n, "ticks": ticks, "ticks_per_s": ticks / w["wall_s"], "agent_ms": med("cpu_ms"),
            "agents_ms": sum(r["cpu_ms"] for r in res), "world_ms": w["cpu_ms"],
            "router_ms": 1000 * (router_cpu[1] - router_cpu[0]) / ticks,
            "msgs_in": med("msgs_in"), "wakeups": med("wakeups"), "switches": med("switches"),
            "heard": med("heard")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("role", nargs="?", choices=["agent", "world"], help=argparse.SUPPRESS)
    ap.add_argument("-n", "--agents", type=int, nargs="+", default=[16, 36, 64])
    ap.add_argument("--pattern", nargs="+", choices=PATTERNS, default=list(PATTERNS))
    ap.add_argument("--ticks", type=int, default=200, help="ticks measured (after the warm-up)")
    ap.add_argument("--warmup", type=int, default=20, help="ticks run before the measurement starts")
    for hidden in ("--port", "--id", "--start", "--end"):
        ap.add_argument(hidden, type=int, help=argparse.SUPPRESS)
    ap.add_argument("--run", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role == "agent":
        return agent_main(args.port, args.run, args.agents[0], args.id, args.pattern[0], args.start, args.end)
    if args.role == "world":
        return world_main(args.port, args.run, args.agents[0], args.start, args.end)
    print(f"# floor: router + world + N agents (zenoh clients), msgpack only, {args.ticks} ticks measured")
    print(f"# {machine()}")
    print(f"{'pattern':>8s} {'N':>4s} {'ticks/s':>7s} {'agent':>7s} {'agents':>8s} {'world':>7s} {'router':>7s} "
          f"{'msgs in':>7s} {'wakeups':>7s} {'ctxsw':>6s} {'heard':>5s}")
    for n in args.agents:
        for pat in args.pattern:
            r = floor_run(n, pat, args.ticks, args.warmup)
            print(f"{pat:>8s} {n:4d} {r['ticks_per_s']:7.1f} {r['agent_ms']:7.2f} {r['agents_ms']:8.1f} "
                  f"{r['world_ms']:7.2f} {r['router_ms']:7.2f} {r['msgs_in']:7.1f} {r['wakeups']:7.1f} "
                  f"{r['switches']:6.1f} {r['heard']:5.0f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
