#!/usr/bin/env python3
"""The floor of the distributed lockstep tick: its message pattern with nothing of ours behind it.

A router, one world process and N agents in processes of K (`--per-process`, as `--agents-per-process`: one
zenoh client session per process connected to the router, the launcher's ZENOH_RUNTIME, BLOCK congestion
control, samples through the agent processes' own inbox with the same wake-ups; a co-hosted agent's beacon
counted in the process), with msgpack payloads of the real messages' shapes and sizes; no planning, no
admission, no record, no monitor. The robots stay at the grid scenario's starts (bench/grid.py), or at a
scenario file's (`--scenario`). Per tick:

- the world puts the clock (k, t, alive list) on `swarm/<run>/clock` and each agent's state on
  `swarm/<run>/agent/<id>/state`, then waits for every agent's command of the tick;
- an agent, on its state, puts its beacon and waits for the clock and the beacons it hears, then puts its
  command (k, v_mps, omega_radps) on `swarm/<run>/agent/<id>/cmd`. Two patterns:
  `cells`: the beacon under its head point's cell (`swarm/<run>/cell/<cx>_<cy>/agent/<id>/beacon`), heard
  from the cells CellGrid.listen_cells names around it; it waits for every beacon of those cells, as the
  real agent does (its wait set plus the peers it hears anyway, agent/neighbours.py);
  `all`: every beacon to everyone (`swarm/<run>/agent/<id>/beacon`, heard as `swarm/<run>/agent/*/beacon`);
  `batch`: the cells of `cells`, one message per process and cell carrying the beacons of its agents whose
  state came in that round (`swarm/<run>/cell/<cx>_<cy>/host/<hid>/beacons`, the protocol in force:
  reconswarm/net/wire/batch.py), heard as `cell/<c>/host/*/beacons`.

CPU per tick is measured over a window of ticks after a warm-up (start-up does not count): each agent and
the world read their own rusage (CPU, context switches: every thread of the process) at the window's
first and last tick; the router's CPU is read from
/proc/<pid>/stat when the world says it is at those ticks.

    .venv/bin/python bench/floor.py -n 16 36 64 --ticks 200
    .venv/bin/python bench/floor.py --scenario deploy/scenarios/paper.toml --per-process 1 5 10
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import json
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
import floor_pattern as fp
from _common import machine, median
from floor_pattern import beacon_bytes, clock_bytes, cmd_bytes, head_points, heard, state_bytes
from grid import grid_scenario

from reconswarm.net.runtime.inbox import Inbox
from reconswarm.net.runtime.session import ZenohOptions, open_session
from reconswarm.net.wire.cells import CellGrid
from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.model import Scenario, load

ROOT = Path(__file__).resolve().parent.parent
PATTERNS = ("cells", "all", "batch")
STALL_S = 60.0  # a process that makes no progress this long gives up (exit 1): the run is reported failed


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


def scenario_of(n: int, path: str | None) -> Scenario:
    """The grid of n agents (bench/grid.py), or a scenario file's agents at their starts."""
    return grid_scenario(n, 10.0) if not path else load(Path(path))


def agent_main(port: int, run: str, s: Scenario, ids: list[int], pattern: str, start: int, end: int,
               per_process: int = 1) -> int:
    """One process hosting the agents `ids` (one session, each agent its own keys and token, as an agent host):
    what a co-hosted agent publishes is counted by the others in the process, not sent back through zenoh."""
    import zenoh


    keys, pts, dt = Keys(run), head_points(s), s.meta.dt_s
    radius = {a: float(s.radii[s.agent_index(a)]) for a in ids}
    hear = {a: heard(s, a, "cells" if pattern == "batch" else pattern)[0] for a in ids}
    n_src = {a: fp.sources(s, a, per_process) for a in ids}  # (batch: the samples a tick brings each agent)
    z = session(port)
    block, remote = zenoh.CongestionControl.BLOCK, zenoh.Locality.REMOTE
    inbox = Inbox(ordered=True)
    grid = CellGrid.for_scenario(s)
    home, hid = {a: grid.cell_of(*pts[a]) for a in ids}, fp.host_of(ids[0], per_process)
    if pattern == "batch":
        pub_batch = {c: z.declare_publisher(keys.host_beacons(c, hid), congestion_control=block) for c in home.values()}
        cells = sorted(set().union(*(grid.listen_cells(*pts[a]) for a in ids)))
        subs = [z.declare_subscriber(keys.host_beacons(c, None), inbox.handler(("cell", c)), allowed_origin=remote)
                for c in cells]
    elif pattern == "cells":
        pub_beacon = {a: z.declare_publisher(keys.in_cell(grid.cell_of(*pts[a]), a, "beacon"), congestion_control=block)
                      for a in ids}
        cells = sorted(set().union(*(grid.listen_cells(*pts[a]) for a in ids)))
        subs = [z.declare_subscriber(keys.cell_agents(c, "beacon"), inbox.handler(("cell", c)), allowed_origin=remote)
                for c in cells]
    else:
        pub_beacon = {a: z.declare_publisher(keys.agent(a, "beacon"), congestion_control=block) for a in ids}
        subs = [z.declare_subscriber(keys.all_agents("beacon"), inbox.handler(("all", None)), allowed_origin=remote)]
    pub_cmd = {a: z.declare_publisher(keys.agent(a, "cmd"), congestion_control=block) for a in ids}
    subs += [z.declare_subscriber(keys.agent(a, "state"), inbox.handler(("own", a), urgent=True)) for a in ids]
    subs.append(z.declare_subscriber(keys.clock, inbox.handler(("clock", None))))
    tokens = [z.liveliness().declare_token(keys.alive_agent(a)) for a in ids]  # last: we are ready to receive
    states: dict[int, set[int]] = {a: set() for a in ids}
    beacons: dict[int, dict[int, int]] = {a: {} for a in ids}  # agent -> tick -> beacons heard
    batches: dict[int, dict[int, int]] = {a: {} for a in ids}  # agent -> tick -> batches heard (batch)
    clocks: set[int] = set()
    k, sent = dict.fromkeys(ids, 0), dict.fromkeys(ids, -1)
    marks: dict[int, tuple[float, int, int, int]] = {}
    done, last = False, time.monotonic()

    def heard_by(sender: int, tick: int) -> None:
        for b in ids:
            if sender in hear[b] and b != sender:
                beacons[b][tick] = beacons[b].get(tick, 0) + 1

    try:
        while not done:
            if time.monotonic() - last > STALL_S:
                raise RuntimeError(f"agents {ids}: stuck at ticks {sorted(set(k.values()))}")
            acting = [a for a in ids if k[a] in states[a]]
            want = None if not acting else max(1, min(
                (n_src[a] - batches[a].get(k[a], 0) if pattern == "batch" else len(hear[a]) - beacons[a].get(k[a], 0))
                + (k[a] not in clocks) for a in acting))
            for _tag, (key, payload, _kind, _src, _at) in inbox.take(want, 1.0, max(1, len(ids) - len(acting))):
                m = msgpack.unpackb(payload, raw=False)
                if key.endswith("/beacon"):
                    heard_by(m["id"], m["k"])
                elif key.endswith("/beacons"):
                    rows = fp.batch_rows(m)
                    for b in ids:
                        if any(r in hear[b] for r, _ in rows):
                            batches[b][rows[0][1]] = batches[b].get(rows[0][1], 0) + 1
                    for r, rk in rows:
                        heard_by(r, rk)
                elif key.endswith("/state"):
                    states[m["id"]].add(m["k"])
                    if m["k"] == start and start not in marks:
                        marks[start] = (cpu_s(), Inbox.samples_in, Inbox.wakeups, switches())
                elif m["end"]:
                    marks[end] = (cpu_s(), Inbox.samples_in, Inbox.wakeups, switches())
                    done = True
                else:
                    clocks.add(m["k"])
            moved = True
            while moved:  # (a co-hosted agent's beacon may complete another's tick)
                moved = False
                out: dict[Any, list[tuple[int, int, float, Any, float]]] = {}  # (batch: cell -> its round's beacons)
                for a in ids:
                    ka = k[a]
                    if ka in states[a] and sent[a] < ka:
                        if pattern == "batch":
                            out.setdefault(home[a], []).append((a, ka, ka * dt, pts[a], radius[a]))
                        else:
                            pub_beacon[a].put(beacon_bytes(a, ka, ka * dt, pts[a], radius[a]))
                        sent[a] = ka
                        heard_by(a, ka)
                        moved = True
                for c, rows_out in out.items():  # (put before any command of the round)
                    pub_batch[c].put(fp.batch_bytes(hid, rows_out))
                for a in ids:
                    ka = k[a]
                    if ka in states[a] and ka in clocks and beacons[a].get(ka, 0) >= len(hear[a]):
                        pub_cmd[a].put(cmd_bytes(a, ka))
                        states[a].discard(ka)
                        beacons[a].pop(ka, None)
                        k[a] = ka + 1
                        last, moved = time.monotonic(), True
            clocks.difference_update([c for c in clocks if c < min(k.values())])
    finally:
        for token in tokens:
            token.undeclare()
        for sub in subs:
            sub.undeclare()
        z.close()
    (c0, m0, w0, s0), (c1, m1, w1, s1) = marks[start], marks[end]
    ticks, per = end - start, len(ids)
    print(json.dumps({"cpu_ms": 1000 * (c1 - c0) / ticks, "agents": per, "msgs_in": (m1 - m0) / ticks / per,
                      "wakeups": (w1 - w0) / ticks / per, "switches": (s1 - s0) / ticks / per,
                      "heard": median([len(h) for h in hear.values()])}), flush=True)
    return 0


def world_main(port: int, run: str, s: Scenario, start: int, end: int) -> int:
    import zenoh

    keys, pts = Keys(run), head_points(s)
    n = len(pts)
    ids = sorted(pts)
    z = session(port)
    block = zenoh.CongestionControl.BLOCK
    inbox = Inbox()
    pub_clock = z.declare_publisher(keys.clock, congestion_control=block)
    pub_state = {a: z.declare_publisher(keys.agent(a, "state"), congestion_control=block) for a in ids}
    subs = [z.declare_subscriber(keys.all_agents("cmd"), inbox.handler()),
            z.liveliness().declare_subscriber(keys.alive_all, inbox.handler(), history=True)]
    try:
        up: set[int] = set()
        deadline = time.monotonic() + STALL_S
        while len(up) < n:  # the readiness barrier: every agent's token (declared after its subscribers)
            if time.monotonic() > deadline:
                raise RuntimeError(f"world: only {len(up)} of {n} agents came up")
            for _tag, (key, _p, kind, _src, _at) in inbox.take(n - len(up), 0.5):
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
                for _tag, (key, payload, _kind, _src, _at) in inbox.take(n - len(got), 1.0):
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


def floor_run(n: int, pattern: str, ticks: int = 200, warmup: int = 20, timeout_s: float = 900.0,
              per_process: int = 1, scenario: str | None = None) -> dict[str, float]:
    """One floor run: CPU-ms per tick per role over `ticks` ticks after `warmup`, samples and wake-ups in per
    agent per tick (medians over the agents; a process of K agents counts a K-th to each), ticks per wall
    second. `per_process`: K consecutive agents per process; `scenario`: a scenario file's agents (n is then
    theirs). Every process is ended by its PID."""
    from reconswarm_bringup.fleet import batch_policy
    from reconswarm_bringup.launcher import ZENOH_RUNTIME

    if pattern not in PATTERNS:
        raise ValueError(f"pattern: expected one of {PATTERNS}, got {pattern!r}")
    if scenario:
        n = len(load(Path(scenario)).agents)
    port, run = free_port(), f"floor{os.getpid()}x{n}{pattern}k{per_process}"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    client_env = dict(env, ZENOH_RUNTIME=ZENOH_RUNTIME)
    me = [sys.executable, str(Path(__file__).resolve())]
    common = ["--port", str(port), "--run", run, "--agents", str(n), "--start", str(warmup),
              "--end", str(warmup + ticks), *(["--scenario", scenario] if scenario else [])]
    groups = [list(range(a, min(a + per_process, n + 1))) for a in range(1, n + 1, per_process)]
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
            for g in groups:
                a = g[0]
                out = (logs / f"agent{a}.out").open("w")
                agents.append(spawn([*me, "agent", "--ids", ",".join(map(str, g)), "--pattern", pattern, *common,
                                     "--per-process", str(per_process)],
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
            res = [json.loads((logs / f"agent{g[0]}.out").read_text()) for g in groups]
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

    for r in res:
        r["agent_ms"] = r["cpu_ms"] / r["agents"]
    return {"n": n, "per_process": per_process, "ticks": ticks, "ticks_per_s": ticks / w["wall_s"],
            "agent_ms": med("agent_ms"), "agents_ms": sum(r["cpu_ms"] for r in res), "world_ms": w["cpu_ms"],
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
    ap.add_argument("--per-process", type=int, nargs="+", default=[1],
                    help="agents per process, K (as --agents-per-process K: an agent host per K agents)")
    ap.add_argument("--scenario", help="a scenario file's agents at their starts instead of the grid (-n ignored)")
    for hidden in ("--port", "--start", "--end"):
        ap.add_argument(hidden, type=int, help=argparse.SUPPRESS)
    ap.add_argument("--ids", help=argparse.SUPPRESS)
    ap.add_argument("--run", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role == "agent":
        return agent_main(args.port, args.run, scenario_of(args.agents[0], args.scenario),
                          [int(a) for a in args.ids.split(",")], args.pattern[0], args.start, args.end,
                          args.per_process[0])
    if args.role == "world":
        return world_main(args.port, args.run, scenario_of(args.agents[0], args.scenario), args.start, args.end)
    print(f"# floor: router + world + N agents (zenoh clients, K per process), msgpack only, {args.ticks} ticks "
          f"measured{' on ' + args.scenario if args.scenario else ''}")
    print(f"# {machine()}")
    print(f"{'pattern':>8s} {'N':>4s} {'K':>3s} {'ticks/s':>7s} {'agent':>7s} {'agents':>8s} {'world':>7s} "
          f"{'router':>7s} {'msgs in':>7s} {'wakeups':>7s} {'ctxsw':>6s} {'heard':>5s}")
    for n in args.agents if not args.scenario else [0]:
        for pat in args.pattern:
            for per in args.per_process:
                r = floor_run(n, pat, args.ticks, args.warmup, per_process=per, scenario=args.scenario)
                print(f"{pat:>8s} {r['n']:4d} {per:3d} {r['ticks_per_s']:7.1f} {r['agent_ms']:7.2f} "
                      f"{r['agents_ms']:8.1f} {r['world_ms']:7.2f} {r['router_ms']:7.2f} {r['msgs_in']:7.1f} "
                      f"{r['wakeups']:7.1f} {r['switches']:6.1f} {r['heard']:5.0f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
