"""Every agent's obstacle knowledge in one (N, B) bit table (reconswarm/paper/swarm_knowledge.py: when this
storage is chosen). Pure, no zenoh.

Bits of obstacle l occupy the byte columns b0[l]:b1[l] of every agent's row. A tick's sharing is two
vectorized steps over all obstacles at once (the changed columns over every link, every known column over
new links), whatever the number of obstacles: the fastest storage while N x B bytes stay small.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import rows_where
from reconswarm.paper.knowledge_bits import NONE, Array, Ints, SwarmKnowledge


class DenseKnowledge(SwarmKnowledge, dense=True):
    """SwarmKnowledge over a dense (N, B) bit table."""

    def __init__(self, samples: Array, start: Ints, count: Ints, n_agents: int, dense: bool | None = None):
        super().__init__(samples, start, count, n_agents)
        owner = np.repeat(np.arange(count.size), count)
        local = np.arange(samples.shape[0]) - start[owner] if samples.shape[0] else NONE
        bit = 8 * self.b0[owner] + local if samples.shape[0] else NONE
        self.byte_of = (bit // 8).astype(np.int64)  # (S,) byte column of each sample
        self.mask_of = (np.uint8(0x80) >> (bit % 8).astype(np.uint8)).astype(np.uint8)  # (S,)
        self.table = np.zeros((n_agents, self.union.size), dtype=np.uint8)  # (N, B)
        self.col_owner = np.repeat(np.arange(count.size), self.nbytes).astype(np.int64)  # (B,) obstacle of a byte
        self._dirty = NONE  # byte columns that changed during the last update (sorted)

    @property
    def bits(self) -> NDArray[np.uint8]:
        """The (N, B) table itself (live: copy it to keep a tick's bits)."""
        return self.table

    def add(self, agents: Ints, samples: Ints) -> None:
        if agents.size:
            np.bitwise_or.at(self.table, (agents, self.byte_of[samples]), self.mask_of[samples])
            self.union = self.union.copy()
            np.bitwise_or.at(self.union, self.byte_of[samples], self.mask_of[samples])
            self._any_known = True
        self._reset()

    def share(self, prev: NDArray[np.uint8], pairs: Ints) -> None:
        if pairs.shape[0] == 0 or self.table.shape[1] == 0 or not prev.any():
            self._reset()
            return
        dst = np.concatenate([pairs[:, 0], pairs[:, 1]])
        src = np.concatenate([pairs[:, 1], pairs[:, 0]])
        order = np.argsort(dst, kind="stable")
        dst, src = dst[order], src[order]
        firsts = np.flatnonzero(np.r_[True, dst[1:] != dst[:-1]])
        reduced = np.bitwise_or.reduceat(prev[src], firsts, axis=0)
        self.table[dst[firsts]] |= reduced
        self._reset()  # after the bits changed: `known` is recomputed from them

    def update(self, agents: Ints, samples: Ints, links: Ints) -> None:
        self.union_prev = self.union  # replaced, never modified in place, when sensing adds to it
        if self.table.shape[1] == 0:
            return
        if not self._any_known:  # nothing to share: only sensing, and every link counts as new next time
            self._link_keys = None
            self._dirty = self._sense(agents, samples)
            self._any_known = bool(self.union.any())
            return
        new = self._new_links(links)
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
            self._dirty = NONE
        else:
            self._dirty = changed[0] if len(changed) == 1 else np.unique(np.concatenate(changed))

    def _sense(self, agents: Ints, samples: Ints) -> Ints:
        """add() for the incremental path; returns the byte columns that changed (sorted, unique)."""
        if agents.size == 0:
            return NONE
        byte, mask = self.byte_of[samples], self.mask_of[samples]  # (Q,)
        fresh = (self.table[agents, byte] & mask) == 0
        if not fresh.any():
            return NONE
        byte, mask, rows = byte[fresh], mask[fresh], agents[fresh]
        np.bitwise_or.at(self.table, (rows, byte), mask)
        self._touched(rows, byte)
        self.union = self.union.copy()
        np.bitwise_or.at(self.union, byte, mask)
        self._any_known = True
        return np.unique(byte)

    def _pack(self, cols: Ints, rows: Ints | None = None) -> NDArray[np.uint64]:
        """table[rows, cols] eight bytes to a uint64 word (zero padded): (R, C) bytes -> (R, W) words."""
        c = cols.shape[0]
        sub = self.table[:, cols] if rows is None else self.table[rows][:, cols]  # (R, C)
        out = np.zeros((sub.shape[0], 8 * ((c + 7) // 8)), dtype=np.uint8)
        out[:, :c] = sub
        return out.view(np.uint64)

    def _or_in(self, cols: Ints, dst: Ints, vals: NDArray[np.uint64]) -> Ints:
        """table[dst, cols] |= vals row by row (dst may repeat); returns the columns that changed (sorted).

        cols (C,), dst (Q,), vals (Q, W) the bytes packed by _pack.
        """
        c = cols.shape[0]
        w = vals.shape[1]
        acc = np.zeros((self.table.shape[0], w), dtype=np.uint64)  # (N, W)
        if w == 1:
            np.bitwise_or.at(acc.reshape(-1), dst, vals.reshape(-1))
        else:
            np.bitwise_or.at(acc, dst, vals)
        cur = self._pack(cols)  # (N, W)
        gain = acc & ~cur
        rows = np.nonzero(gain.any(axis=1))[0]  # (R,) agents that learn something
        if rows.size == 0:
            return NONE
        self.table[np.ix_(rows, cols)] = (cur[rows] | acc[rows]).view(np.uint8)[:, :c]
        r, at = gain[rows].view(np.uint8)[:, :c].nonzero()
        self._touched(rows[r], cols[at])
        return np.unique(cols[at])

    def _touched(self, rows: Ints, cols: Ints) -> None:
        """Bytes (rows[q], cols[q]) gained bits: those agents know those obstacles, their hulls are stale."""
        obs = self.col_owner[cols]
        self.known[rows, obs] = True
        self._hull_at[rows, obs] = None
        self.version += 1

    def knows_rows(self, l: int, rows: Ints) -> NDArray[np.bool_]:
        return np.any(self.table[rows, self.b0[l]:self.b1[l]] != 0, axis=1)

    def knows(self, l: int) -> NDArray[np.bool_]:
        return np.any(self.table[:, self.b0[l]:self.b1[l]] != 0, axis=1)

    def block(self, i: int, l: int) -> NDArray[np.uint8]:
        return self.table[i, self.b0[l]:self.b1[l]]
