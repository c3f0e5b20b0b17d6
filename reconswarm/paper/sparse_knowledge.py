"""Every agent's obstacle knowledge, a block of bits per (agent, obstacle) it knows (reconswarm/paper/
swarm_knowledge.py: when this storage is chosen). Pure, no zenoh.

Only agents that know something of obstacle l hold a block of l: a table (N, M) gives each agent's row in
l's block array, or -1. Memory grows with what the agents know, at most one block per (agent, obstacle)
known, instead of a bit per contour sample for every agent: a swarm far from every obstacle holds nothing.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from reconswarm.paper.knowledge_bits import NONE, Array, Ints, SwarmKnowledge

_NONE = NONE
_ZERO = np.zeros(1, dtype=np.int64)


class SparseKnowledge(SwarmKnowledge, dense=False):
    """SwarmKnowledge over per-obstacle block arrays (`bits`, the dense table, is built on demand)."""

    def __init__(self, samples: Array, start: Ints, count: Ints, n_agents: int, dense: bool | None = None):
        super().__init__(samples, start, count, n_agents)
        m = count.size
        owner = np.repeat(np.arange(m), count).astype(np.int64)
        local = np.arange(samples.shape[0]) - start[owner] if samples.shape[0] else _NONE
        self.obstacle_of = owner  # (S,) obstacle of each sample
        self.byte_of = (local // 8).astype(np.int64)  # (S,) byte within its obstacle's block
        self.mask_of = (np.uint8(0x80) >> (local % 8).astype(np.uint8)).astype(np.uint8)  # (S,)
        self.row = np.full((n_agents, m), -1, dtype=np.int32)  # (N, M) agent's row in blocks[l], -1: none
        self.blocks = [np.zeros((0, int(b)), dtype=np.uint8) for b in self.nbytes]  # l -> (capacity, nbytes[l])
        self.used = [0] * m  # rows of blocks[l] in use
        self._dirty: dict[int, Ints] = {}  # obstacle -> its block's byte columns changed in the last update

    # ------------------------------------------------------------------------------------ storage

    @property
    def bits(self) -> NDArray[np.uint8]:
        """The dense table (N, B): every agent's bits of every obstacle (built on demand: small swarms, tests)."""
        out = np.zeros((self.n, self.union.size), dtype=np.uint8)
        for l in range(self.count.size):
            has = np.flatnonzero(self.row[:, l] >= 0)
            out[has, self.b0[l]:self.b1[l]] = self.blocks[l][self.row[has, l]]
        return out

    def _get(self, l: int, agents: Ints) -> NDArray[np.uint8]:
        """The blocks of obstacle l of these agents, zeros where an agent holds none. (R,) -> (R, nbytes[l])"""
        r = self.row[agents, l]
        has = r >= 0
        if has.all():
            return self.blocks[l][r]
        out = np.zeros((agents.size, int(self.nbytes[l])), dtype=np.uint8)
        out[has] = self.blocks[l][r[has]]
        return out

    def _rows(self, l: int, agents: Ints) -> NDArray[np.int32]:
        """Rows of obstacle l's blocks for these agents, made (zeroed) for those without one. (R,) -> (R,)"""
        r = self.row[agents, l]
        if (r >= 0).all():
            return r
        fresh = np.unique(agents[r < 0])
        end = self.used[l] + fresh.size
        blk = self.blocks[l]
        if end > blk.shape[0]:
            grown = np.zeros((max(16, 2 * end), blk.shape[1]), dtype=np.uint8)
            grown[:blk.shape[0]] = blk
            self.blocks[l] = grown
        self.row[fresh, l] = np.arange(self.used[l], end, dtype=np.int32)
        self.used[l] = end
        return self.row[agents, l]

    def _by_obstacle(self, samples: Ints) -> list[tuple[int, Ints]]:
        """[(l, positions q of samples of obstacle l)] in increasing l."""
        obs = self.obstacle_of[samples]
        order = np.argsort(obs, kind="stable")
        cuts = np.flatnonzero(np.diff(obs[order])) + 1
        return [(int(obs[g[0]]), g) for g in np.split(order, cuts)]

    # ----------------------------------------------------------------------------- add and share

    def add(self, agents: Ints, samples: Ints) -> None:
        """Mark sensed samples: agent index (Q,), global sample index (Q,)."""
        if agents.size:
            self._sense(agents, samples)
        self._reset()

    def share(self, prev: NDArray[np.uint8], pairs: Ints) -> None:
        """OR into each agent what its linked neighbours knew at the previous tick.

        prev (N, B) the dense bits at k-1 (`bits`); pairs (E, 2) the linked pairs (i < j) at tick k.
        """
        if pairs.shape[0] == 0 or prev.shape[1] == 0 or not prev.any():
            self._reset()
            return
        dst = np.concatenate([pairs[:, 0], pairs[:, 1]])
        src = np.concatenate([pairs[:, 1], pairs[:, 0]])
        for l in range(self.count.size):
            block = prev[:, self.b0[l]:self.b1[l]]
            keep = block[src].any(axis=1)
            if keep.any():
                self._or_in(l, np.arange(block.shape[1], dtype=np.int64), dst[keep], block[src[keep]])
        self._reset()  # after the bits changed: `known` is recomputed from them

    def update(self, agents: Ints, samples: Ints, links: Ints) -> None:
        """See SwarmKnowledge.update. Per obstacle l, only links whose source holds a block of l carry
        anything, and one OR step serves them all: over l's columns anyone knew when some new link carries
        l, else over the changed ones. (An old link may carry every known column too: outside the changed
        ones, its source's bits are those the previous update already passed over it.)"""
        self.union_prev = self.union  # replaced, never modified in place, when sensing adds to it
        if self.union.size == 0:
            return
        if not self._any_known:  # nothing to share: only sensing, and every link counts as new next time
            self._link_keys = None
            self._dirty = self._sense(agents, samples)
            self._any_known = bool(self.union.any())
            return
        new = self._new_links(links)
        dst = np.concatenate([links[:, 0], links[:, 1]])  # (2E,)
        order = np.argsort(dst, kind="stable")  # (once: every obstacle's links then come by destination)
        dst, src = dst[order], np.concatenate([links[:, 1], links[:, 0]])[order]
        fresh = None if new is None or not new.any() else np.concatenate([new, new])[order]
        # What share needs from the bits before sensing: dirty columns over every link, all over new ones.
        todo: list[tuple[int, Ints, Ints, NDArray[np.uint8]]] = []
        rows_src = self.row[src]  # (2E, M) each link source's row of every obstacle
        carries = rows_src >= 0  # (2E, M)
        for l in np.flatnonzero(carries.any(axis=0)).tolist():  # obstacles some link's source knows
            r, c = rows_src[:, l], carries[:, l]
            dirty = self._dirty.get(l, _NONE)
            known, fc = _NONE, c
            if fresh is not None:
                fc = fresh & c
                if fc.any():
                    known = self.union_prev[self.b0[l]:self.b1[l]].nonzero()[0]  # what sharing can bring
            if known.size:
                has = np.flatnonzero(c if dirty.size else fc)
                todo.append((l, known, dst[has], self.blocks[l][r[has]][:, known]))
            elif dirty.size:
                has = np.flatnonzero(c)
                todo.append((l, dirty, dst[has], self.blocks[l][r[has]][:, dirty]))
        changed = self._sense(agents, samples)
        for l, cols, d, vals in todo:
            got = self._or_in(l, cols, d, vals, ordered=True)
            if got.size:
                changed[l] = np.union1d(changed[l], got) if l in changed else got
        self._dirty = changed

    def _sense(self, agents: Ints, samples: Ints) -> dict[int, Ints]:
        """Mark sensed samples; returns, per obstacle, the byte columns that changed (sorted, unique)."""
        out: dict[int, Ints] = {}
        if agents.size == 0:
            return out
        for l, q in self._by_obstacle(samples):
            a, byte, mask = agents[q], self.byte_of[samples[q]], self.mask_of[samples[q]]
            r = self.row[a, l]
            cur = np.zeros(q.size, dtype=np.uint8)
            has = r >= 0
            cur[has] = self.blocks[l][r[has], byte[has]]
            fresh = (cur & mask) == 0
            if not fresh.any():
                continue
            a, byte, mask = a[fresh], byte[fresh], mask[fresh]
            rows = self._rows(l, a)  # (first: it may grow blocks[l])
            np.bitwise_or.at(self.blocks[l], (rows, byte), mask)
            self._touched(a, l)
            self.union = self.union.copy()
            np.bitwise_or.at(self.union, self.b0[l] + byte, mask)
            out[l] = np.unique(byte)
        if out:
            self._any_known = True
        return out

    def _or_in(self, l: int, cols: Ints, dst: Ints, vals: NDArray[np.uint8], ordered: bool = False) -> Ints:
        """blocks of l at [dst, cols] |= vals row by row (dst may repeat); returns the columns that changed.

        cols (C,) byte columns of l's block, dst (Q,) (ordered: already sorted), vals (Q, C).
        """
        if dst.size == 1:
            acc, who = vals, dst
        else:
            if not ordered:
                order = np.argsort(dst, kind="stable")
                dst, vals = dst[order], vals[order]
            firsts = np.flatnonzero(dst[1:] != dst[:-1]) + 1
            firsts = np.concatenate([_ZERO, firsts]) if firsts.size else _ZERO
            acc = np.bitwise_or.reduceat(vals, firsts, axis=0)  # (U, C)
            who = dst[firsts]  # (U,) distinct agents
        cur = self._get(l, who)[:, cols]
        gain = acc & ~cur
        learn = np.flatnonzero(gain.any(axis=1))
        if learn.size == 0:
            return _NONE
        rows = self._rows(l, who[learn])
        if cols.size == self.blocks[l].shape[1]:  # every column (a new link shares them all)
            self.blocks[l][rows] = cur[learn] | acc[learn]
        else:
            self.blocks[l][rows[:, None], cols[None, :]] = cur[learn] | acc[learn]
        self._touched(who[learn], l)
        return cols[gain[learn].any(axis=0)]

    def _touched(self, agents: Ints, l: int) -> None:
        """These agents gained bits of obstacle l: they know it, their hulls of it are stale."""
        self.known[agents, l] = True
        self._hull_at[agents, l] = None
        self.version += 1

    # ---------------------------------------------------------------------------------- reading

    def knows_rows(self, l: int, rows: Ints) -> NDArray[np.bool_]:
        r = self.row[rows, l]
        out = r >= 0
        out[out] = self.blocks[l][r[out]].any(axis=1)
        return out

    def block(self, i: int, l: int) -> NDArray[np.uint8]:
        r = int(self.row[i, l])
        return self.blocks[l][r] if r >= 0 else np.zeros(int(self.nbytes[l]), dtype=np.uint8)
