"""Every agent's obstacle knowledge at once, for the in-process engine (reconswarm/paper/knowledge.py states the
rule). Pure, no zenoh.

Knowledge of obstacle l is a bitset over l's contour samples (one bit a sample, l's block of bytes). Only
agents that know something of l hold a block of l: a table (N, M) gives each agent's row in l's block
array, or -1. Memory grows with what the agents know, at most one block per (agent, obstacle) known,
instead of a bit per contour sample for every agent: a swarm far from every obstacle holds nothing.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import convex_hull, merge_hull, rows_where

Array = NDArray[np.float64]
Ints = NDArray[np.int64]
_NONE = np.zeros(0, dtype=np.int64)
_ZERO = np.zeros(1, dtype=np.int64)


class SwarmKnowledge:
    """Every agent's knowledge as bitsets over the world's contour samples (in-process engine only).

    One agent's knowledge of one obstacle is a block of bytes: a bytes key for the hull cache, so agents
    of a linked group share their hulls' computation.

    `update` is `add` then `share` done incrementally (the engine's path); `add` and `share` remain for
    callers that hold their own previous bits (`bits`, the dense (N, B) table), and reset the incremental state.
    """

    def __init__(self, samples: Array, start: Ints, count: Ints, n_agents: int):
        self.samples = samples
        self.start, self.count = start, count
        m = count.size
        self.nbytes = ((count + 7) // 8).astype(np.int64)  # (M,) bytes of each obstacle's block
        self.b0 = np.concatenate([[0], np.cumsum(self.nbytes)[:-1]]).astype(np.int64) if m else self.nbytes
        self.b1 = self.b0 + self.nbytes  # (the dense layout: obstacle l's block at bytes b0[l]:b1[l])
        owner = np.repeat(np.arange(m), count).astype(np.int64)
        local = np.arange(samples.shape[0]) - start[owner] if samples.shape[0] else _NONE
        self.obstacle_of = owner  # (S,) obstacle of each sample
        self.byte_of = (local // 8).astype(np.int64)  # (S,) byte within its obstacle's block
        self.mask_of = (np.uint8(0x80) >> (local % 8).astype(np.uint8)).astype(np.uint8)  # (S,)
        self.n = n_agents
        self.row = np.full((n_agents, m), -1, dtype=np.int32)  # (N, M) agent's row in blocks[l], -1: none
        self.blocks = [np.zeros((0, int(b)), dtype=np.uint8) for b in self.nbytes]  # l -> (capacity, nbytes[l])
        self.used = [0] * m  # rows of blocks[l] in use
        self._cache: dict[tuple[int, bytes], Array] = {}
        self._last: dict[tuple[int, int], tuple[NDArray[np.uint8], Array]] = {}  # (i, l) -> last (block, hull)
        # OR of every agent's bits, dense layout (only sensing adds to it: sharing moves bits between agents). (B,)
        self.union = np.zeros(int(self.b1[-1]) if m else 0, dtype=np.uint8)
        self.union_prev = self.union.copy()  # the union before the last update (B,)
        self._link_keys: Ints | None = None  # sorted i * N + j of the last update's links
        self._dirty: dict[int, Ints] = {}  # obstacle -> its block's byte columns changed in the last update
        self._any_known = False  # whether union has any bit
        self.known = np.zeros((n_agents, m), dtype=bool)  # (N, M) knows(l) for every l
        self._hull_at = np.full((n_agents, m), None, dtype=object)  # (N, M) hull(i, l), None: stale
        self.version = 0  # bumped whenever any agent's knowledge (so any hull) may have changed

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

    def _reset(self) -> None:
        """After add or share: every incremental shortcut starts over."""
        self._link_keys = None
        self._hull_at[:] = None
        self.version += 1
        for l in range(self.count.size):
            self.known[:, l] = self.knows(l)

    def update(self, agents: Ints, samples: Ints, links: Ints) -> None:
        """`add(agents, samples)` then `share(prev, links)` with prev the bits before this call.

        Same result, computed over what can change: over a link that already existed at the previous
        update, the previous update passed on everything but the byte columns that changed during it, so
        only those are shared again; a new link shares every column anyone knew. Only links whose source
        holds a block of the obstacle carry anything. links (E, 2), i < j.
        """
        self.union_prev = self.union  # replaced, never modified in place, when sensing adds to it
        if self.union.size == 0:
            return
        if not self._any_known:  # nothing to share: only sensing, and every link counts as new next time
            self._link_keys = None
            self._dirty = self._sense(agents, samples)
            self._any_known = bool(self.union.any())
            return
        keys = links[:, 0] * self.n + links[:, 1]  # (E,) increasing
        last = self._link_keys
        if last is not None and last.shape == keys.shape and last.tobytes() == keys.tobytes():
            new = None  # the same links as last time (the common case)
        elif last is None or last.size == 0:
            new = np.ones(keys.shape[0], dtype=bool)
        else:
            at = np.minimum(np.searchsorted(last, keys), last.size - 1)
            new = last[at] != keys
        self._link_keys = keys if new is None or bool((keys[1:] >= keys[:-1]).all()) else np.sort(keys)
        dst = np.concatenate([links[:, 0], links[:, 1]])  # (2E,)
        src = np.concatenate([links[:, 1], links[:, 0]])
        fresh = None if new is None or not new.any() else np.concatenate([new, new])
        # What share needs from the bits before sensing: dirty columns over every link, all over new ones.
        todo: list[tuple[int, Ints, Ints, NDArray[np.uint8]]] = []
        rows_src = self.row[src]  # (2E, M) each link source's row of every obstacle
        carries = rows_src >= 0  # (2E, M)
        for l in np.flatnonzero(carries.any(axis=0)).tolist():  # obstacles some link's source knows
            r, c = rows_src[:, l], carries[:, l]
            dirty = self._dirty.get(l, _NONE)
            if dirty.size:
                has = np.flatnonzero(c)
                todo.append((l, dirty, dst[has], self.blocks[l][r[has]][:, dirty]))
            if fresh is not None:
                known = self.union_prev[self.b0[l]:self.b1[l]].nonzero()[0]  # what sharing can bring
                has = np.flatnonzero(fresh & c)
                if known.size and has.size:
                    todo.append((l, known, dst[has], self.blocks[l][r[has]][:, known]))
        changed = self._sense(agents, samples)
        for l, cols, d, vals in todo:
            got = self._or_in(l, cols, d, vals)
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

    def _or_in(self, l: int, cols: Ints, dst: Ints, vals: NDArray[np.uint8]) -> Ints:
        """blocks of l at [dst, cols] |= vals row by row (dst may repeat); returns the columns that changed.

        cols (C,) byte columns of l's block, dst (Q,), vals (Q, C).
        """
        if dst.size == 1:
            acc, who = vals, dst
        else:
            order = np.argsort(dst, kind="stable")
            d = dst[order]
            firsts = np.flatnonzero(d[1:] != d[:-1]) + 1
            firsts = np.concatenate([_ZERO, firsts]) if firsts.size else _ZERO
            acc = np.bitwise_or.reduceat(vals[order], firsts, axis=0)  # (U, C)
            who = d[firsts]  # (U,) distinct agents
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

    def knows(self, l: int) -> NDArray[np.bool_]:
        """(N,) whether each agent knows any of obstacle l."""
        return self.knows_rows(l, np.arange(self.n, dtype=np.int64))

    def knows_rows(self, l: int, rows: Ints) -> NDArray[np.bool_]:
        """knows(l)[rows]. rows (R,) -> (R,)"""
        r = self.row[rows, l]
        out = r >= 0
        out[out] = self.blocks[l][r[out]].any(axis=1)
        return out

    def block(self, i: int, l: int) -> NDArray[np.uint8]:
        """Agent i's bits of obstacle l (its block; zeros if it holds none)."""
        r = int(self.row[i, l])
        return self.blocks[l][r] if r >= 0 else np.zeros(int(self.nbytes[l]), dtype=np.uint8)

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
        block = self.block(i, l)
        hull = self.hull_of_bits(l, block, self._last.get((i, l)))
        self._last[(i, l)] = (block.copy(), hull)  # where agent i's next hull of l grows from
        return hull

    def hulls(self, rows: Ints, l: int) -> list[Array]:
        """[hull(i, l) for i in rows], reusing each agent's hull while its knowledge of l is unchanged."""
        got = self._hull_at[rows, l].tolist()
        for q, h in enumerate(got):
            if h is None:
                i = int(rows[q])
                got[q] = self._hull_at[i, l] = self.hull(i, l)
        return got

    def union_hull(self, l: int, bits: NDArray[np.uint8]) -> Array | None:
        """Hull of what any agent knew of obstacle l (dense bits (N, B)); None if nobody knows it."""
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
