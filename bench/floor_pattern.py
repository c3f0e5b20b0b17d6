"""The floor's message pattern, pure: who hears whom, and payloads of the real messages' shapes and sizes
(bench/floor.py runs it with real processes)."""

from __future__ import annotations

import math
from typing import Any

import msgpack

from reconswarm.net.cells import CellGrid
from reconswarm.net.wire import VERSION
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
