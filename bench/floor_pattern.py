"""The floor's message pattern, pure: who hears whom, and payloads of the real messages' shapes and sizes
(bench/floor.py runs it with real processes)."""

from __future__ import annotations

import math
from typing import Any

import msgpack

from reconswarm.net.wire.cells import CellGrid
from reconswarm.net.wire.wire import VERSION
from reconswarm.scenario.model import Scenario

XY = tuple[float, float]


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
    # (`cells` and `batch` hear the same peers: `batch` carries them in one message per host and cell)
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


def host_of(aid: int, per_process: int) -> int:
    """The host's key id of agent aid (its process's lowest id: processes of K consecutive ids from 1)."""
    return (aid - 1) // per_process * per_process + 1


def sources(s: Scenario, agent_id: int, per_process: int) -> int:
    """How many batches a tick brings the agent in the `batch` pattern: one per (other host, cell) among the peers
    it hears."""
    pts, grid, me = head_points(s), CellGrid.for_scenario(s), host_of(agent_id, per_process)
    return len({(h, grid.cell_of(*pts[a])) for a in heard(s, agent_id, "cells")[0]
                if (h := host_of(a, per_process)) != me})


def batch_bytes(hid: int, beacons: list[tuple[int, int, float, XY, float]]) -> bytes:
    """Same map as reconswarm/net/wire/batch.py's batch_to_wire: (id, k, t, p, radius) rows in packed columns."""
    from reconswarm.net.wire import wire
    from reconswarm.net.wire.batch import batch_to_wire

    return batch_to_wire(hid, [wire.Beacon(a, k, t, p[0], p[1], r, 0) for a, k, t, p, r in beacons])


def batch_rows(m: dict[str, Any]) -> list[tuple[int, int]]:
    """(id, k) of each beacon of an unpacked batch (its rows read, as a receiver reads them)."""
    from reconswarm.net.wire.batch import ROW

    return [(r[0], r[1]) for r in ROW.iter_unpack(m["rows"])]
