"""Known obstacles O_i(t) and their sharing between agents. Pure, no zenoh.

The rule, identical in every mode:

    K_i,l(k) = hull( K_i,l(k-1) ∪ scan_i,l(k) ∪ ⋃_{j : ‖p_i(k) - p_j(k)‖ <= link range} K_j,l(k-1) )

that is, an agent merges what it senses at tick k with what its linked neighbours knew at tick k-1:
sharing has **one tick of delay**, and shares everything known (so knowledge spreads hop by hop
through a connected group). Only the hull matters (obstacles are convex), so what travels is hull
vertices. `KnownObstacles` holds one agent's knowledge as hulls (the agent process); `SwarmKnowledge`
holds the whole swarm's as bitsets over the world's contour samples (the in-process engine), which is
the same rule made cheap for thousands of agents: both give the same canonical hulls.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from agent.planner import ObstacleView
from reconswarm.geometry import Edges, convex_hull, merge_hull, signed_distance

Array = NDArray[np.float64]


@dataclass
class KnownObstacles:
    """One agent's obstacle knowledge: obstacle id -> canonical hull (V, 2)."""

    hulls: dict[str, Array] = field(default_factory=dict)
    rev: int = 0  # bumped whenever any hull grows

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


def obstacle_view(p: Array, n_rows: int, n_cols: int,
                  entries: list[tuple[int, int, Array]]) -> ObstacleView:
    """Distances from agents to the hulls they know, as the planner's (N, M) table.

    p (N, 2); entries: (row, column, hull) with columns in increasing obstacle id.
    """
    view = ObstacleView(np.zeros((n_rows, n_cols)), np.zeros((n_rows, n_cols, 2)),
                        np.zeros((n_rows, n_cols), dtype=bool))
    if not entries:
        return view
    rows = np.array([e[0] for e in entries], dtype=np.int64)
    cols = np.array([e[1] for e in entries], dtype=np.int64)
    d, nx, ny = signed_distance(p[rows, 0], p[rows, 1], Edges.of([e[2] for e in entries]))
    view.d[rows, cols] = d
    view.n[rows, cols, 0] = nx
    view.n[rows, cols, 1] = ny
    view.valid[rows, cols] = True
    return view


class SwarmKnowledge:
    """Every agent's knowledge as bitsets over the world's contour samples (in-process engine only).

    Bits of obstacle l occupy a byte-aligned block, so one agent's knowledge of one obstacle is a bytes
    key for the hull cache: agents of a linked group share their hulls' computation.
    """

    def __init__(self, samples: Array, start: NDArray[np.int64], count: NDArray[np.int64], n_agents: int):
        self.samples = samples
        self.start, self.count = start, count
        nbytes = (count + 7) // 8
        self.b0 = np.concatenate([[0], np.cumsum(nbytes)[:-1]]).astype(np.int64) if count.size else nbytes
        self.b1 = self.b0 + nbytes
        owner = np.repeat(np.arange(count.size), count)
        local = np.arange(samples.shape[0]) - start[owner] if samples.shape[0] else np.zeros(0, np.int64)
        bit = 8 * self.b0[owner] + local if samples.shape[0] else np.zeros(0, np.int64)
        self.byte_of = (bit // 8).astype(np.int64)
        self.mask_of = (np.uint8(0x80) >> (bit % 8).astype(np.uint8)).astype(np.uint8)
        self.bits = np.zeros((n_agents, int(self.b1[-1]) if count.size else 0), dtype=np.uint8)
        self._cache: dict[tuple[int, bytes], Array] = {}

    def add(self, agents: NDArray[np.int64], samples: NDArray[np.int64]) -> None:
        """Mark sensed samples: agent index (Q,), global sample index (Q,)."""
        if agents.size:
            np.bitwise_or.at(self.bits, (agents, self.byte_of[samples]), self.mask_of[samples])

    def share(self, prev: NDArray[np.uint8], pairs: NDArray[np.int64]) -> None:
        """OR into each agent what its linked neighbours knew at the previous tick.

        prev (N, B) the bits at k-1; pairs (E, 2) the linked pairs (i < j) at tick k.
        """
        if pairs.shape[0] == 0 or self.bits.shape[1] == 0 or not prev.any():
            return
        dst = np.concatenate([pairs[:, 0], pairs[:, 1]])
        src = np.concatenate([pairs[:, 1], pairs[:, 0]])
        order = np.argsort(dst, kind="stable")
        dst, src = dst[order], src[order]
        firsts = np.flatnonzero(np.r_[True, dst[1:] != dst[:-1]])
        reduced = np.bitwise_or.reduceat(prev[src], firsts, axis=0)
        rows = dst[firsts]
        self.bits[rows] |= reduced

    def knows(self, l: int) -> NDArray[np.bool_]:
        """(N,) whether each agent knows any of obstacle l."""
        return np.any(self.bits[:, self.b0[l]:self.b1[l]] != 0, axis=1)

    def hull_of_bits(self, l: int, block: NDArray[np.uint8]) -> Array:
        key = (l, block.tobytes())
        hull = self._cache.get(key)
        if hull is None:
            flags = np.unpackbits(block)[: int(self.count[l])].astype(bool)
            s0 = int(self.start[l])
            hull = convex_hull(self.samples[s0:s0 + int(self.count[l])][flags])
            if len(self._cache) > 200_000:
                self._cache.clear()
            self._cache[key] = hull
        return hull

    def hull(self, i: int, l: int) -> Array:
        return self.hull_of_bits(l, self.bits[i, self.b0[l]:self.b1[l]])

    def union_hull(self, l: int, bits: NDArray[np.uint8]) -> Array | None:
        """Hull of what any agent knew of obstacle l (bits (N, B)); None if nobody knows it."""
        block = np.bitwise_or.reduce(bits[:, self.b0[l]:self.b1[l]], axis=0)
        if not block.any():
            return None
        return self.hull_of_bits(l, block)
