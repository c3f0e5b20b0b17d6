"""The planner seam: one tick's inputs for the agents being computed, batched over rows (N), and the head
point's velocity u (N, 2) a planner returns (then eq. 3 turns u into the unicycle's (v, ω), as for every planner).

The in-process engine passes every agent as a row; an agent process passes itself (N = 1), or the agents it
hosts. Rows are in increasing agent id; neighbour tables in increasing neighbour id; hulls in obstacle-id order.
A planner fills only what it declares it needs (`needs_tables`, `needs_hulls`); the rest is left empty.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from reconswarm.paper.deadlock import StallState
from reconswarm.paper.planner import Neighbours, ObstacleView
from reconswarm.scenario.model import Scenario

Array = NDArray[np.float64]


@dataclass
class Tick:
    """What the rows' planners know at tick k (the same information as the paper's agent)."""

    k: int
    dt_s: float
    p: Array  # (N, 2) head points at k
    theta: Array  # (N,) headings at k
    r: Array  # (N,) radii
    center: Array  # (N, 2) the formation's centre: p*, or each agent's copy of the virtual leader
    offset: Array  # (N, 2) each agent's slot Δ_i: its target is center + offset
    lead_vel: Array | None  # (N, 2) the virtual leader's velocity (benchmark only), else None
    stall: StallState  # Remark 1's per-row history (the caller owns it; a planner may ignore it)
    err: Array | None = None  # (N,) ‖p - (center + offset)‖ when the caller has it
    nb: Neighbours | None = None  # needs_tables: peers within d_max,ij
    ob: ObstacleView | None = None  # needs_tables: distances and normals to the known hulls within reach
    heard: Neighbours | None = None  # needs_hulls: peers heard within link range (head points, radii)
    hulls: Sequence[Sequence[Array]] | None = None  # needs_hulls: each row's known hulls (V, 2), by obstacle id


class Planner(Protocol):
    """One planner for the rows it was made for (`registry.make(s, ids)`): it may keep state per row."""

    needs_tables: bool  # wants Tick.nb and Tick.ob (the paper's repulsion tables)
    needs_hulls: bool  # wants Tick.heard and Tick.hulls

    def command(self, t: Tick) -> Array:
        """The head points' velocities u (N, 2) for the tick's rows."""
        ...


def cruise_speed_mps(s: Scenario) -> float:
    """The scenario's speed bound for a planner that takes one: the world's limit if it has one, else the
    paper's cruise speed R_c k_att (the attraction's largest speed, eq. 9)."""
    if s.world.max_speed_mps > 0:
        return s.world.max_speed_mps
    return s.planner.target_radius_m * s.planner.k_att


def row_ids(s: Scenario, ids: Sequence[int] | None) -> list[int]:
    """The agent ids of a planner's rows: all the scenario's agents (in increasing id) when None."""
    return [int(i) for i in (s.ids if ids is None else ids)]
