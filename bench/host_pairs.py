#!/usr/bin/env python3
"""What an agent host spends per (remote sample, receiving agent) pair: its routing (decode, admission, the batches)
and its nodes taking the beacons, in one process on a real zenoh session (nothing is sent).

The host holds agents 1..K of the sparse grid of N (bench/grid.py: a row of the grid, as `--agents-per-process K`
packs them), each listening to the cells around its start (agent/neighbours.py); every other agent's beacon of a
tick, from its start under its cell, comes in its host's batch for that cell (hosts of K consecutive ids), a
remote sample routed to the hosted agents that listen to that cell
(`AgentHost.route`), then each node steps with its batch (`AgentNode.step`: no state yet, so the step is the
beacons' bookkeeping). Per row: the beacons the host takes a tick, the (beacon, receiving agent) pairs, and the
microseconds per pair of routing and of routing plus the nodes' steps (the best of `--reps` ticks: the cost
without the machine's other work). Another checkout's code is measured with its path first:
`PYTHONPATH=OTHER .venv/bin/python bench/host_pairs.py` (a checkout whose gates have no shared admission gets a
gate of its own per agent, as its `agent/process.py` makes them).

    .venv/bin/python bench/host_pairs.py -n 64 144 400 -k 8 48 200
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import inspect
import math
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
import zenoh
from _common import command_line, machine
from grid import grid_scenario

from agent.host import AgentHost
from agent.hosted import HostedAgent
from agent.neighbours import Cells
from agent.node import AgentNode
from reconswarm.net.runtime.inbox import Inbox, Rejections
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.trust.admission import Admission
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.cells import CellGrid
from reconswarm.net.wire.keys import Keys

try:  # one beacon message per host and cell (a checkout before it: a sample per beacon)
    from reconswarm.net.wire.batch import batch_to_wire
except ImportError:
    batch_to_wire = None  # type: ignore[assignment]


def measure(z: zenoh.Session, n: int, k: int, reps: int) -> tuple[int, int, float, float]:
    """(beacons a tick, pairs a tick, µs per pair routing, µs per pair routing and stepping) for a host of k in n."""
    s, keys = grid_scenario(n, 10.0), Keys(f"pairs-{n}-{k}")
    ids = [a.id for a in s.agents[:k]]
    if "adm" in inspect.signature(Gate).parameters:
        adm = Admission(s)
        gates = {a: Gate(s, f"agent-{a}", adm=adm) for a in ids}
    else:  # (a checkout before the host's one admission)
        gates = {a: Gate(s, f"agent-{a}") for a in ids}
    zid = str(z.info.zid())
    links = {a: HostedAgent(AgentNode(s, a, 0.0), keys, z, Rejections(f"agent {a}"), gates[a], None, zid)
             for a in ids}
    host = AgentHost(z, keys, links, Inbox(ordered=True))
    try:
        grid = CellGrid.for_scenario(s)
        for a, link in links.items():
            start = link.node.nb.start[a]
            host.listen(a, Cells(grid.cell_of(*start), grid.listen_cells(*start)))
        heard = set().union(*(c for c in host.cells.listening.values() if c is not None))
        best_route = best_all = math.inf
        pairs = beacons = 0
        starts = s.starts
        peers = [(spec, float(starts[i][0]), float(starts[i][1]), s.agents[i // k * k].id)
                 for i, spec in enumerate(s.agents) if i >= k]
        for tick in range(reps):
            items = []
            by_host: dict[tuple[int, Any], list[wire.Beacon]] = {}  # (the peers' hosts of k: one batch per cell)
            for spec, x, y, hid in peers:
                cell = grid.cell_of(x, y)
                if cell in heard:
                    b = wire.Beacon(spec.id, tick, 0.05 * tick, x, y, spec.radius_m, 0)
                    if batch_to_wire is None:  # (a checkout before the batches: a sample per beacon)
                        key = keys.in_cell(cell, spec.id, "beacon")
                        items.append((("cell", cell), (key, wire.beacon_to_wire(b), "PUT", "peer", 0.0)))
                    by_host.setdefault((hid, cell), []).append(b)
            if batch_to_wire is not None:
                items = [(("cell", cell), (keys.host_beacons(cell, hid), batch_to_wire(hid, rows), "PUT", "peer", 0.0))
                         for (hid, cell), rows in by_host.items()]
            t0 = time.perf_counter()
            batches = host.route(items)
            t1 = time.perf_counter()
            for a, batch in batches.items():
                links[a].node.step(batch, 1.0)
            t2 = time.perf_counter()
            best_route, best_all = min(best_route, t1 - t0), min(best_all, t2 - t0)
            beacons, pairs = sum(map(len, by_host.values())), sum(len(b) for b in batches.values())
        return beacons, pairs, 1e6 * best_route / max(1, pairs), 1e6 * best_all / max(1, pairs)
    finally:
        host.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-n", type=int, nargs="+", default=[64, 144, 400], help="agents in the grid")
    ap.add_argument("-k", type=int, nargs="+", default=[8, 48, 200], help="agents in the host (K < N)")
    ap.add_argument("--reps", type=int, default=60, help="ticks per row (the best counts)")
    args = ap.parse_args()
    print(f"# host_pairs: {machine()}")
    print(f"# reproduce: {command_line()}")
    print(f"{'N':>5s} {'K':>4s} {'beacons':>8s} {'pairs':>6s} {'route us':>9s} {'+steps us':>9s}  (per pair, a tick)")
    z = zenoh.open(ZenohOptions((), ("tcp/127.0.0.1:0",), "peer").config())
    try:
        for n in args.n:
            for k in (k for k in args.k if k < n):
                beacons, pairs, route_us, all_us = measure(z, n, k, args.reps)
                print(f"{n:5d} {k:4d} {beacons:8d} {pairs:6d} {route_us:9.2f} {all_us:9.2f}", flush=True)
    finally:
        z.close()
    print(f"# after: {machine()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
