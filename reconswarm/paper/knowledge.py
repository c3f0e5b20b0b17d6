"""Known obstacles O_i(t) and their sharing between agents. Pure, no zenoh.

The rule, identical in every mode:

    K_i,l(k) = hull( K_i,l(k-1) ∪ scan_i,l(k) ∪ ⋃_{j : ‖p_i(k) - p_j(k)‖ <= link range} K_j,l(k-1) )

that is, an agent merges what it senses at tick k with what its linked neighbours knew at tick k-1:
sharing has **one tick of delay**, and shares everything known (so knowledge spreads hop by hop
through a connected group). Only the hull matters (obstacles are convex), so what travels is hull
vertices. `KnownObstacles` holds one agent's knowledge as hulls (the agent process); `SwarmKnowledge`
(reconswarm/paper/swarm_knowledge.py) holds the whole swarm's as bitsets over the contour samples of the
obstacles each agent knows (the in-process engine), which is the same rule made cheap for many agents:
both give the same canonical hulls.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import Edges, convex_hull, merge_hull, signed_distance
from reconswarm.paper.planner import ObstacleView
from reconswarm.paper.swarm_knowledge import SwarmKnowledge

Array = NDArray[np.float64]

__all__ = ["KnownObstacles", "SwarmKnowledge", "obstacle_view"]


@dataclass
class KnownObstacles:
    """One agent's obstacle knowledge: obstacle id -> canonical hull (V, 2)."""

    hulls: dict[str, Array] = field(default_factory=dict)

    def merge(self, oid: str, points: Array) -> bool:
        """Add points (P, 2) to obstacle `oid`; True if its hull changed."""
        if points.shape[0] == 0:
            return False
        old = self.hulls.get(oid)
        new = convex_hull(points) if old is None else merge_hull(old, points)
        if old is not None and new.shape == old.shape and np.array_equal(new, old):
            return False
        self.hulls[oid] = new
        return True

    def merge_all(self, sets: dict[str, Array]) -> bool:
        changed = False
        for oid in sorted(sets):
            changed |= self.merge(oid, sets[oid])
        return changed

    def sorted_items(self) -> list[tuple[str, Array]]:
        return sorted(self.hulls.items())


def obstacle_view(p: Array, n_rows: int, n_cols: int, rows: NDArray[np.int64], cols: NDArray[np.int64],
                  edges: Edges) -> ObstacleView:
    """Distances from agents to the hulls they know, as the planner's (N, M) table.

    p (N, 2); entry q: agent rows[q], column cols[q] (columns in increasing obstacle id), the hull whose
    edges are row q of `edges` (Edges.of(hulls)). Entries not given are invalid.
    """
    view = ObstacleView(np.zeros((n_rows, n_cols)), np.zeros((n_rows, n_cols, 2)),
                        np.zeros((n_rows, n_cols), dtype=bool))
    if rows.size == 0:
        return view
    d, nx, ny = signed_distance(p[rows, 0], p[rows, 1], edges)
    view.d[rows, cols] = d
    view.n[rows, cols, 0] = nx
    view.n[rows, cols, 1] = ny
    view.valid[rows, cols] = True
    return view
