"""navground's behaviours (ORCA, HRVO, HL, social force) behind the seam, one behaviour per row.

Each tick a row's behaviour gets what the paper's agent has: its head point and heading, its last command as
its velocity, the peers heard within link range as `core.Neighbor` discs (at rest: the wire carries head points,
not velocities), every hull it knows as line obstacles (one `core.LineSegment` per edge, a point hull as a
zero-length segment), and its slot p* + Δ_i as a `core.Target.Point`. The head point is holonomic (eq. 3), so
the kinematics are `Omni` with the scenario's speed bound; `compute_cmd(dt)`'s velocity, in the world frame,
is u. A behaviour keeps state between calls (its last command): each row gets one `compute_cmd` per tick.
Set beyond navground's defaults, each for a reason:

- optimal speed = max speed = the scenario's speed bound (`seam.cruise_speed_mps`): the paper's cruise speed;
- radius = the agent's radius, safety margin = the scenario's d_safe (the paper's clearance);
- horizon = the larger of link and sensing range (navground's 5 m would leave out most of what the agent knows);
- target tolerance = converge_tol / 2 (a behaviour stops once within it; the mission needs every |e_i| <= tol);
- orientation 0 (the head point has no heading of its own): the behaviour's frame is the world's, whatever the
  robot's heading (navground computes in single precision, so a rotation would round).

navground is an optional extra: without it, making one of these planners is one line naming the extra (exit 2).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from reconswarm.errors import BadInput
from reconswarm.planners.seam import Tick, cruise_speed_mps, row_ids
from reconswarm.scenario.model import Scenario

Array = NDArray[np.float64]

MISSING = "planner {name}: navground is not installed (pip install 'reconswarm[navground]')"


def load_core(name: str) -> Any:
    """navground.core, or BadInput naming the extra."""
    try:
        import navground.core as core
    except ImportError:
        raise BadInput(MISSING.format(name=name)) from None
    return core


class NavgroundPlanner:
    needs_tables = False
    needs_hulls = True

    def __init__(self, s: Scenario, ids: Sequence[int] | None, behavior: str, name: str) -> None:
        core = self.core = load_core(name)
        speed = cruise_speed_mps(s)
        p = s.planner
        self.tolerance = 0.5 * p.converge_tol_m
        self.behaviours: list[Any] = []
        for aid in row_ids(s, ids):
            spec = s.agents[s.agent_index(aid)]
            b = core.Behavior.make_type(behavior)
            b.kinematics = core.kinematics.OmnidirectionalKinematics(speed)
            b.radius = spec.radius_m
            b.safety_margin = p.d_safe_m
            b.optimal_speed = speed
            b.horizon = max(p.link_range_m, p.sensing_range_m)
            self.behaviours.append(b)
        n = len(self.behaviours)
        self.velocity = np.zeros((n, 2))  # each row's last command
        self.goal = np.full((n, 2), np.nan)  # each row's target point, as last set
        self._segments: dict[int, tuple[Array, list[Any]]] = {}  # id(hull) -> (hull, its edges)

    def command(self, t: Tick) -> Array:
        core, n = self.core, t.p.shape[0]
        goal = t.center + t.offset
        u = np.zeros((n, 2))
        zero = np.zeros(2)
        for i, b in enumerate(self.behaviours[:n]):
            if not np.array_equal(goal[i], self.goal[i]):
                b.target = core.Target.Point(goal[i], self.tolerance)
                self.goal[i] = goal[i]
            b.position = t.p[i]
            b.velocity = self.velocity[i]
            state = b.environment_state
            neighbours = []
            if t.heard is not None:
                nb = t.heard
                for q in nb.valid[i].nonzero()[0].tolist():
                    neighbours.append(core.Neighbor(nb.p[i, q], float(nb.r[i, q]), zero))
            state.neighbors = neighbours
            state.line_obstacles = [seg for h in (t.hulls[i] if t.hulls is not None else ()) for seg in self._edges(h)]
            u[i] = b.compute_cmd(t.dt_s, core.Frame.absolute).velocity
        self.velocity[:n] = u
        return u

    def _edges(self, hull: Array) -> list[Any]:
        """The hull's edges as line segments (kept while the hull is: hulls change only when knowledge grows)."""
        got = self._segments.get(id(hull))
        if got is not None and got[0] is hull:
            return got[1]
        v = hull.shape[0]
        seg = self.core.LineSegment
        if v == 1:
            edges = [seg(hull[0], hull[0])]
        else:
            edges = [seg(hull[j], hull[(j + 1) % v]) for j in range(v if v > 2 else 1)]
        if len(self._segments) > 10_000:
            self._segments.clear()
        self._segments[id(hull)] = (hull, edges)
        return edges


BEHAVIOURS = {"orca": "ORCA", "hrvo": "HRVO", "hl": "HL", "social-force": "SocialForce"}  # name -> navground's


def orca(s: Scenario, ids: Sequence[int] | None = None) -> NavgroundPlanner:
    return NavgroundPlanner(s, ids, BEHAVIOURS["orca"], "orca")


def hrvo(s: Scenario, ids: Sequence[int] | None = None) -> NavgroundPlanner:
    return NavgroundPlanner(s, ids, BEHAVIOURS["hrvo"], "hrvo")


def hl(s: Scenario, ids: Sequence[int] | None = None) -> NavgroundPlanner:
    return NavgroundPlanner(s, ids, BEHAVIOURS["hl"], "hl")


def social_force(s: Scenario, ids: Sequence[int] | None = None) -> NavgroundPlanner:
    return NavgroundPlanner(s, ids, BEHAVIOURS["social-force"], "social-force")
