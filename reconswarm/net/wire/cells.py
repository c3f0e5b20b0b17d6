"""Spatial cells of the key space: who an agent needs to hear, independent of N.

The law is local: an agent uses a peer only within `reach_m` (link range + hysteresis for sharing, or
2 r_max + d_max for repulsion). Beacons and obstacle sets are published under the cell of the sender's
position (`swarm/<run>/cell/<cx>_<cy>/agent/<id>/...`); an agent subscribes to the cells that intersect
the disk around its position of radius reach + 3 V dt, where V bounds any robot's speed, so every peer
that can matter at the next two ticks publishes in a cell it already hears. Pure: no zenoh.

Geometry (all lengths in metres):
    width_m = link_range_m + hysteresis_m + 2 V dt    (no robot crosses a cell in one tick)
    cell_of(p) = (floor(px / width), floor(py / width))
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from reconswarm.paper.link import HYSTERESIS_M
from reconswarm.scenario.model import Scenario
from reconswarm.scenario.wire_limits import int_from_text

Cell = tuple[int, int]
MAX_CELL = 999_999_999  # a cell coordinate's bound in a key (9 digits)


def speed_bound_mps(s: Scenario) -> float:
    """V: no head point moves faster. The world's limit if it has one; else the planner's bound: the
    attraction is at most R_c k_att (eq. 9), each repulsion term at most |Ψ| (eq. 11, bounded at d_min),
    and a robot between two neighbours and an obstacle meets at most a few of them at full strength, so
    2 |Ψ| plus the stall push is a generous bound in practice. A violation is detected, not assumed away:
    a beacon from outside the expected set within reach is reported (lockstep's determinism)."""
    p = s.planner
    if s.world.max_speed_mps > 0:
        return s.world.max_speed_mps
    return p.target_radius_m * p.k_att + 2.0 * abs(p.psi_mps) + p.perturbation_mps


@dataclass(frozen=True)
class CellGrid:
    width_m: float
    reach_m: float  # a peer beyond this centre distance contributes nothing to an agent's tick
    step_m: float  # V dt: the most any robot moves in one tick

    @classmethod
    def for_scenario(cls, s: Scenario) -> CellGrid:
        p = s.planner
        step = speed_bound_mps(s) * s.meta.dt_s
        reach = max(p.link_range_m + HYSTERESIS_M, 2.0 * float(s.radii.max()) + p.d_max_m)
        return cls(width_m=reach + 2.0 * step, reach_m=reach, step_m=step)

    def cell_of(self, x: float, y: float) -> Cell:
        return math.floor(x / self.width_m), math.floor(y / self.width_m)

    @property
    def listen_radius_m(self) -> float:
        """reach + 3 V dt: the radius of the disk whose cells an agent listens to."""
        return self.reach_m + 3.0 * self.step_m

    def listen_cells(self, x: float, y: float) -> frozenset[Cell]:
        """Every cell that intersects the disk of radius `listen_radius_m` around (x, y)."""
        rad, w = self.listen_radius_m, self.width_m
        xs, ys = _spans(x, rad, w, 0), _spans(y, rad, w, 0)
        r2 = rad * rad
        return frozenset((cx, cy) for cx, dx2 in xs for cy, dy2 in ys if dx2 + dy2 <= r2)

    def listen_margin_m(self, x: float, y: float) -> float:
        """How far (x, y) can move and `listen_cells` stay the same: the smallest gap between the radius and a
        cell's distance, over the cells it names and the ring around them (those beyond are a cell width
        farther), at most a cell width. A distance to a square changes no more than the point moves."""
        rad, w = self.listen_radius_m, self.width_m
        xs, ys = _spans(x, rad, w, 1), _spans(y, rad, w, 1)
        return min(w, min(abs(math.sqrt(dx2 + dy2) - rad) for _, dx2 in xs for _, dy2 in ys))

    @property
    def matter_m(self) -> float:
        """reach + 2 V dt: the farthest centre distance at k-1 from which a peer can be within reach at k."""
        return self.reach_m + 2.0 * self.step_m

    def may_matter(self, own: tuple[float, float], peer: tuple[float, float]) -> bool:
        """Can a peer at `peer` at tick k-1 be within reach of us at tick k (we at `own` at k-1)?"""
        # (hypot: a distance beyond the float range is inf, not an OverflowError as a square of 1e308 is)
        return math.hypot(own[0] - peer[0], own[1] - peer[1]) <= self.matter_m


def _spans(v: float, rad: float, w: float, ring: int) -> list[tuple[int, float]]:
    """Along one axis: the cells c (of width w) the interval [v - rad, v + rad] meets, and `ring` more on each side,
    each with the squared distance from v to the cell's [c w, (c + 1) w] (0 inside it). The nearest point of a
    square to a point is the nearest on each axis, so a cell's squared distance is its column's plus its row's."""
    lo, hi = math.floor((v - rad) / w) - ring, math.floor((v + rad) / w) + ring
    return [(c, (min(max(v, c * w), (c + 1) * w) - v) ** 2) for c in range(lo, hi + 1)]


def cell_chunk(c: Cell) -> str:
    """The key chunk of a cell: "<cx>_<cy>" (integers, may be negative)."""
    return f"{c[0]}_{c[1]}"


def chunk_cell(chunk: str) -> Cell:
    """Inverse of cell_chunk (canonical integers alone: `01_0` is another key than cell (1, 0)'s); ValueError for
    anything else."""
    a, sep, b = chunk.partition("_")
    cx, cy = int_from_text(a, -MAX_CELL, MAX_CELL), int_from_text(b, -MAX_CELL, MAX_CELL)
    if not sep or cx is None or cy is None:
        raise ValueError(f"bad cell {chunk!r}")
    return cx, cy
