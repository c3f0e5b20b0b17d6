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

from reconswarm.geometry.plane import Edges, convex_hull, merge_hull, rows_where, signed_distance
from reconswarm.paper.planner import ObstacleView

Array = NDArray[np.float64]
_NONE = np.zeros(0, dtype=np.int64)


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


class SwarmKnowledge:
    """Every agent's knowledge as bitsets over the world's contour samples (in-process engine only).

    Bits of obstacle l occupy a byte-aligned block, so one agent's knowledge of one obstacle is a bytes
    key for the hull cache: agents of a linked group share their hulls' computation.

    `update` is `add` then `share` done incrementally (the engine's path); `add` and `share` remain for
    callers that hold their own previous bits, and reset the incremental state.
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
        self.bits = np.zeros((n_agents, int(self.b1[-1]) if count.size else 0), dtype=np.uint8)  # (N, B)
        self._cache: dict[tuple[int, bytes], Array] = {}
        self._last: dict[tuple[int, int], tuple[NDArray[np.uint8], Array]] = {}  # (i, l) -> last (block, hull)
        # OR of every agent's bits (only sensing adds to it: sharing moves bits between agents). (B,)
        self.union = np.zeros(self.bits.shape[1], dtype=np.uint8)
        self.union_prev = self.union.copy()  # the union before the last update (B,)
        self._link_keys: NDArray[np.int64] | None = None  # sorted i * N + j of the last update's links
        self._dirty = _NONE  # byte columns that changed during the last update (sorted)
        self._any_known = False  # whether union has any bit
        self.col_owner = np.repeat(np.arange(count.size), nbytes).astype(np.int64)  # (B,) obstacle of a byte
        self.known = np.zeros((n_agents, count.size), dtype=bool)  # (N, M) knows(l) for every l
        self._hull_at = np.full((n_agents, count.size), None, dtype=object)  # (N, M) hull(i, l), None: stale
        self.version = 0  # bumped whenever any agent's knowledge (so any hull) may have changed

    def add(self, agents: NDArray[np.int64], samples: NDArray[np.int64]) -> None:
        """Mark sensed samples: agent index (Q,), global sample index (Q,)."""
        if agents.size:
            np.bitwise_or.at(self.bits, (agents, self.byte_of[samples]), self.mask_of[samples])
            self.union = self.union.copy()
            np.bitwise_or.at(self.union, self.byte_of[samples], self.mask_of[samples])
            self._any_known = True
        self._reset()

    def share(self, prev: NDArray[np.uint8], pairs: NDArray[np.int64]) -> None:
        """OR into each agent what its linked neighbours knew at the previous tick.

        prev (N, B) the bits at k-1; pairs (E, 2) the linked pairs (i < j) at tick k.
        """
        if pairs.shape[0] == 0 or self.bits.shape[1] == 0 or not prev.any():
            self._reset()
            return
        dst = np.concatenate([pairs[:, 0], pairs[:, 1]])
        src = np.concatenate([pairs[:, 1], pairs[:, 0]])
        order = np.argsort(dst, kind="stable")
        dst, src = dst[order], src[order]
        firsts = np.flatnonzero(np.r_[True, dst[1:] != dst[:-1]])
        reduced = np.bitwise_or.reduceat(prev[src], firsts, axis=0)
        rows = dst[firsts]
        self.bits[rows] |= reduced
        self._reset()  # after the bits changed: `known` is recomputed from them

    def _reset(self) -> None:
        """After add or share: every incremental shortcut starts over."""
        self._link_keys = None
        self._hull_at[:] = None
        self.version += 1
        for l in range(self.count.size):
            self.known[:, l] = self.knows(l)

    def update(self, agents: NDArray[np.int64], samples: NDArray[np.int64], links: NDArray[np.int64]) -> None:
        """`add(agents, samples)` then `share(prev, links)` with prev the bits before this call.

        Same result, computed over what can change: over a link that already existed at the previous
        update, the previous update passed on everything but the byte columns that changed during it, so
        only those are shared again; a new link shares every column anyone knew. links (E, 2), i < j.
        """
        n = self.bits.shape[0]
        self.union_prev = self.union  # replaced, never modified in place, when sensing adds to it
        if self.bits.shape[1] == 0:
            return
        if not self._any_known:  # nothing to share: only sensing, and every link counts as new next time
            self._link_keys = None
            self._dirty = self._sense(agents, samples)
            self._any_known = bool(self.union.any())
            return
        keys = links[:, 0] * n + links[:, 1]  # (E,) increasing
        last = self._link_keys
        if last is not None and last.shape == keys.shape and last.tobytes() == keys.tobytes():
            new = None  # the same links as last time (the common case)
        elif last is None or last.size == 0:
            new = np.ones(keys.shape[0], dtype=bool)
        else:
            at = np.minimum(np.searchsorted(last, keys), last.size - 1)
            new = last[at] != keys
        self._link_keys = keys if new is None or bool((keys[1:] >= keys[:-1]).all()) else np.sort(keys)
        dirty = self._dirty
        # What share needs from the bits before sensing: dirty columns over every link, all over new ones.
        share_dirty = bool(links.shape[0] and dirty.size)
        if share_dirty:
            dst = np.concatenate([links[:, 0], links[:, 1]])  # (2E,)
            src = np.concatenate([links[:, 1], links[:, 0]])
            prev_dirty = self._pack(dirty)  # (N, W)
        share_new = new is not None and bool(new.any())
        if share_new and new is not None:
            known = self.union_prev.nonzero()[0]  # columns anyone knew: the only ones sharing can bring
            fresh_links = rows_where(links, new)  # (E', 2)
            dst_new = np.concatenate([fresh_links[:, 0], fresh_links[:, 1]])  # (2E',)
            src_new = np.concatenate([fresh_links[:, 1], fresh_links[:, 0]])
            vals_new = self._pack(known, src_new)  # (2E', W')
        changed = [self._sense(agents, samples)]
        if share_dirty:
            changed.append(self._or_in(dirty, dst, prev_dirty[src]))
        if share_new:
            changed.append(self._or_in(known, dst_new, vals_new))
        changed = [c for c in changed if c.size]
        if not changed:
            self._dirty = _NONE
        else:
            self._dirty = changed[0] if len(changed) == 1 else np.unique(np.concatenate(changed))

    def _sense(self, agents: NDArray[np.int64], samples: NDArray[np.int64]) -> NDArray[np.int64]:
        """add() for the incremental path; returns the byte columns that changed (sorted, unique)."""
        if agents.size == 0:
            return _NONE
        byte, mask = self.byte_of[samples], self.mask_of[samples]  # (Q,)
        fresh = (self.bits[agents, byte] & mask) == 0
        if not fresh.any():
            return _NONE
        byte, mask, rows = byte[fresh], mask[fresh], agents[fresh]
        np.bitwise_or.at(self.bits, (rows, byte), mask)
        self._touched(rows, byte)
        self.union = self.union.copy()
        np.bitwise_or.at(self.union, byte, mask)
        return np.unique(byte)

    def _pack(self, cols: NDArray[np.int64], rows: NDArray[np.int64] | None = None) -> NDArray[np.uint64]:
        """bits[rows, cols] eight bytes to a uint64 word (zero padded): (R, C) bytes -> (R, W) words."""
        c = cols.shape[0]
        sub = self.bits[:, cols] if rows is None else self.bits[rows][:, cols]  # (R, C)
        out = np.zeros((sub.shape[0], 8 * ((c + 7) // 8)), dtype=np.uint8)
        out[:, :c] = sub
        return out.view(np.uint64)

    def _or_in(self, cols: NDArray[np.int64], dst: NDArray[np.int64], vals: NDArray[np.uint64]) -> NDArray[np.int64]:
        """bits[dst, cols] |= vals row by row (dst may repeat); returns the columns that changed (sorted).

        cols (C,), dst (Q,), vals (Q, W) the bytes packed by _pack.
        """
        c = cols.shape[0]
        w = vals.shape[1]
        acc = np.zeros((self.bits.shape[0], w), dtype=np.uint64)  # (N, W)
        if w == 1:
            np.bitwise_or.at(acc.reshape(-1), dst, vals.reshape(-1))
        else:
            np.bitwise_or.at(acc, dst, vals)
        cur = self._pack(cols)  # (N, W)
        gain = acc & ~cur
        rows = np.nonzero(gain.any(axis=1))[0]  # (R,) agents that learn something
        if rows.size == 0:
            return _NONE
        self.bits[np.ix_(rows, cols)] = (cur[rows] | acc[rows]).view(np.uint8)[:, :c]
        r, at = gain[rows].view(np.uint8)[:, :c].nonzero()
        self._touched(rows[r], cols[at])
        return np.unique(cols[at])

    def _touched(self, rows: NDArray[np.int64], cols: NDArray[np.int64]) -> None:
        """Bytes (rows[q], cols[q]) gained bits: those agents know those obstacles, their hulls are stale."""
        obs = self.col_owner[cols]
        self.known[rows, obs] = True
        self._hull_at[rows, obs] = None
        self.version += 1

    def knows(self, l: int) -> NDArray[np.bool_]:
        """(N,) whether each agent knows any of obstacle l."""
        return np.any(self.bits[:, self.b0[l]:self.b1[l]] != 0, axis=1)

    def knows_rows(self, l: int, rows: NDArray[np.int64]) -> NDArray[np.bool_]:
        """knows(l)[rows]. rows (R,) -> (R,)"""
        return np.any(self.bits[rows, self.b0[l]:self.b1[l]] != 0, axis=1)

    def hull_of_bits(self, l: int, block: NDArray[np.uint8], since: tuple[NDArray[np.uint8], Array] | None = None
                     ) -> Array:
        """Canonical hull of the samples of obstacle l flagged in block. since: an earlier (block, hull) whose
        bits block includes: then the hull grows from that hull by the new samples only (merge_hull, as an
        agent process does), instead of from every sample."""
        key = (l, block.tobytes())
        hull = self._cache.get(key)
        if hull is None:
            if since is not None and not (since[0] & ~block).any():
                hull = merge_hull(since[1], self._samples_of(l, block & ~since[0]))
            else:
                hull = convex_hull(self._samples_of(l, block))
            if len(self._cache) > 200_000:
                self._cache.clear()
            self._cache[key] = hull
        return hull

    def _samples_of(self, l: int, block: NDArray[np.uint8]) -> Array:
        """The contour samples of obstacle l flagged in block (its bytes). -> (P, 2)"""
        flags = np.unpackbits(block)[: int(self.count[l])].astype(bool)
        s0 = int(self.start[l])
        return rows_where(self.samples[s0:s0 + int(self.count[l])], flags)

    def hull(self, i: int, l: int) -> Array:
        block = self.bits[i, self.b0[l]:self.b1[l]]
        hull = self.hull_of_bits(l, block, self._last.get((i, l)))
        self._last[(i, l)] = (block.copy(), hull)  # where agent i's next hull of l grows from
        return hull

    def hulls(self, rows: NDArray[np.int64], l: int) -> list[Array]:
        """[hull(i, l) for i in rows], reusing each agent's hull while its knowledge of l is unchanged."""
        got = self._hull_at[rows, l].tolist()
        for q, h in enumerate(got):
            if h is None:
                i = int(rows[q])
                got[q] = self._hull_at[i, l] = self.hull(i, l)
        return got

    def union_hull(self, l: int, bits: NDArray[np.uint8]) -> Array | None:
        """Hull of what any agent knew of obstacle l (bits (N, B)); None if nobody knows it."""
        block = np.bitwise_or.reduce(bits[:, self.b0[l]:self.b1[l]], axis=0)
        if not block.any():
            return None
        return self.hull_of_bits(l, block)

    def union_hull_before(self, l: int) -> Array | None:
        """union_hull(l, bits before the last update), from the running union."""
        block = self.union_prev[self.b0[l]:self.b1[l]]
        if not block.any():
            return None
        return self.hull_of_bits(l, block)
