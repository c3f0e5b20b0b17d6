#!/usr/bin/env python3
"""One agent's lockstep tick as a path of hops: from the samples that bring its state and its peers' beacons into
its process to its command put on the wire, every call into the project's own code, in order, and the files they
visit.

An agent host of the paper's scenario (agent 1 alone, or agents 1..K) on a zenoh session of its own (a peer linked
to nobody: what it puts goes nowhere) is fed what a lockstep run brings it, as raw samples through its routing: the
liveliness tokens, then each tick the world's clock, its state batch, and every other agent's beacon in a batch of
one from its own host (what the paper's other agents put at K = 1: they stand still at their starts here). Ticks
before `--tick` warm the host and its nodes up (cells declared, tables built); tick `--tick` is traced with
`sys.setprofile`: a hop is a call of a project function (agent/, simworld/, monitor/, reconswarm/,
reconswarm_bringup/), counted by the file it lives in. The host's rounds are the runtime's own (`Runtime._round`,
its answers loop), so the path is the one a run takes, without the inbox's wait.

Works on any checkout with agent hosts (PYTHONPATH the checkout): `--checkout DIR` runs the same in DIR's .venv.

    bench/tick_hops.py
    bench/tick_hops.py --agents-per-process 5 --checkout /path/to/older/worktree
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import inspect
import json
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("agent", "simworld", "monitor", "reconswarm", "reconswarm_bringup")


def trace_tick(k_traced: int, per_process: int) -> dict[str, Any]:
    """Build the host, feed ticks 0..k_traced, trace the last; the hops as a dict (for --json)."""
    import zenoh

    import agent
    from agent.host import AgentHost
    from agent.hosted import HostedAgent
    from agent.node import AgentNode
    from agent.robot_io import keys_robot
    from reconswarm.net.runtime import inbox as inbox_mod
    from reconswarm.net.runtime.inbox import Rejections
    from reconswarm.net.runtime.lifecycle import Stopper
    from reconswarm.net.runtime.runtime import Runtime
    from reconswarm.net.runtime.session import ZenohOptions
    from reconswarm.net.trust.admission import Admission
    from reconswarm.net.trust.gate import Gate
    from reconswarm.net.wire import wire
    from reconswarm.net.wire.batch import batch_to_wire
    from reconswarm.net.wire.cells import CellGrid
    from reconswarm.net.wire.hostwire import state_batches
    from reconswarm.net.wire.keys import Keys
    from reconswarm.scenario.model import load

    code = Path(agent.__file__).resolve().parents[1]  # (the checkout whose code runs: PYTHONPATH)
    s = load(code / "deploy" / "scenarios" / "paper.toml")
    ids = tuple(a.id for a in s.agents)[:per_process]
    keys, now = Keys("hops"), time.monotonic()
    z = zenoh.open(ZenohOptions((), ("tcp/127.0.0.1:0",), "peer").config())
    # The inbox of an agent host: one class with `ordered`, or (older checkouts) the agent package's own TaggedInbox.
    inbox = inbox_mod.Inbox(ordered=True) if "ordered" in inspect.signature(inbox_mod.Inbox).parameters else \
        __import__("agent.tagged_inbox", fromlist=["TaggedInbox"]).TaggedInbox()
    batched: dict[str, Any] = {"batched": len(ids) > 1} if "batched" in inspect.signature(AgentNode).parameters else {}
    nodes = {a: AgentNode(s, a, now, **batched) for a in ids}
    adm = Admission(s)
    own = str(z.info.zid()) if len(ids) > 1 else None
    links = {a: HostedAgent(nodes[a], keys, z, Rejections(f"agent {a}"), Gate(s, f"agent-{a}", adm=adm), keys_robot,
                            own, inbox.callback(("own", a), urgent=True)) for a in ids}
    host = AgentHost(z, keys, links, inbox)
    rt = Runtime(z, "hops", Stopper(), inbox, 0.05)
    grid = CellGrid.for_scenario(s)
    heads = {a.id: (float(a.start_m[0] + s.head_offsets[i]), float(a.start_m[1])) for i, a in enumerate(s.agents)}
    alive = tuple(sorted(heads))
    every = ("all", None)

    def items_of(k: int) -> list[tuple[Any, tuple[str, bytes, str, str, float]]]:
        t = time.monotonic()
        out: list[tuple[Any, tuple[str, bytes, str, str, float]]] = []
        out.append((every, (keys.clock, wire.clock_to_wire(wire.Clock(k, k * s.meta.dt_s, alive)), "PUT", "world", t)))
        for a in heads:
            if a in ids:
                continue
            cell = grid.cell_of(*heads[a])
            b = wire.Beacon(a, k, k * s.meta.dt_s, heads[a][0], heads[a][1], float(s.radii[s.agent_index(a)]), 0)
            out.append((("cell", cell), (keys.host_beacons(cell, a), batch_to_wire(a, [b]), "PUT", f"peer-{a}", t)))
        sts = [wire.State(a, k, k * s.meta.dt_s, heads[a][0] - 0.5, heads[a][1], 0.0, heads[a][0], heads[a][1])
               for a in ids]
        ((payload, _n),) = state_batches(min(ids), sts)
        out.append((("states", None), (keys.host(min(ids), "state"), payload, "PUT", "world", t)))
        return out

    def tick(items: list[tuple[Any, tuple[str, bytes, str, str, float]]]) -> None:
        """The runtime's rounds for tick k's samples: route, step, answers; again while co-hosted agents handed
        each other something (their beacons: what the next round's route brings)."""
        active: dict[Any, Any] = dict(nodes)
        for _round in range(20):
            batches = host.route(items, time.monotonic())
            items = []
            rt._round(list(active), active, host, batches, [], {})
            while answers := host.answers(time.monotonic()):
                rt._round([w for w in active if w in answers], active, host, answers, [], {})
            if not any(host.pending().values()):
                break

    tokens = [(every, (keys.alive_agent(a), b"", "PUT", "world" if a in ids else f"peer-{a}", now)) for a in heads]
    tokens.append((every, (keys.alive_simworld, b"", "PUT", "world", now)))
    host.route(tokens, now)
    for k in range(k_traced):
        tick(items_of(k))
    before = [n.k for n in nodes.values()]
    calls: list[tuple[str, str]] = []
    roots = tuple(str(code / p) + os.sep for p in PACKAGES)

    def profile(frame: Any, event: str, _arg: Any) -> None:
        if event == "call" and frame.f_code.co_filename.startswith(roots):
            calls.append((os.path.relpath(frame.f_code.co_filename, code), frame.f_code.co_name))

    items = items_of(k_traced)  # (built before the trace: the world's and the peers' work, not the host's)
    sys.setprofile(profile)
    try:
        tick(items)
    finally:
        sys.setprofile(None)
    after = [n.k for n in nodes.values()]
    host.close()
    z.close()
    files = Counter(f for f, _fn in calls)
    return {"agents": len(ids), "tick": k_traced, "commanded": after, "before": before, "hops": len(calls),
            "functions": len(set(calls)), "files": dict(files.most_common()),
            "top": [f"{n:5d}  {f}:{fn}" for (f, fn), n in Counter(calls).most_common(25)]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents-per-process", type=int, default=1, metavar="K", help="agents 1..K in one host")
    ap.add_argument("--tick", type=int, default=3, help="the tick traced (the ones before warm the host up)")
    ap.add_argument("--checkout", action="append", default=[], help="also measure another checkout (its .venv)")
    ap.add_argument("--functions", action="store_true", help="also the 25 most called functions")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.json:
        print(json.dumps(trace_tick(args.tick, args.agents_per_process)))
        return 0
    print(f"# tick_hops: python {sys.version.split()[0]}, load average {os.getloadavg()[0]:.2f}")
    print(f"# reproduce: bench/tick_hops.py {' '.join(sys.argv[1:])}")
    for where in [ROOT, *(Path(c).resolve() for c in args.checkout)]:
        py = where / ".venv" / "bin" / "python"
        cmd = [str(py), str(where / "bench" / "tick_hops.py"), "--json", "--tick", str(args.tick),
               "--agents-per-process", str(args.agents_per_process)]
        if not (where / "bench" / "tick_hops.py").exists():  # (an older checkout: this script, its code)
            cmd[1] = str(Path(__file__).resolve())
        env = {**os.environ, "PYTHONPATH": str(where)}
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=where, check=False)
        if r.returncode != 0:
            print(f"{where}: failed: {r.stderr.strip().splitlines()[-1:]}")
            continue
        got = json.loads(r.stdout.strip().splitlines()[-1])
        print(f"\n## {where} (K = {got['agents']}, tick {got['tick']}: ticks commanded {got['before']} -> "
              f"{got['commanded']})")
        print(f"{got['hops']} hops (calls of project functions), {got['functions']} functions, "
              f"{len(got['files'])} files:")
        for f, n in got["files"].items():
            print(f"  {n:5d}  {f}")
        if args.functions:
            print("the most called functions:")
            for line in got.get("top", []):
                print(f"  {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
