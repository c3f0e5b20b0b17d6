"""The interface every storage of the swarm's obstacle knowledge shares, and what they share of it (reading
hulls, which links are new). reconswarm/paper/swarm_knowledge.py describes the storages. Pure, no zenoh.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import convex_hull, merge_hull, rows_where

Array = NDArray[np.float64]
Ints = NDArray[np.int64]
NONE = np.zeros(0, dtype=np.int64)
DENSE_MAX_BYTES = 64 * 2**20  # the largest dense (N, B) table made without being asked


class SwarmKnowledge:
    """Every agent's knowledge as bitsets over the world's contour samples (in-process engine only).

    One agent's knowledge of one obstacle is a block of bytes: a bytes key for the hull cache, so agents
    of a linked group share their hulls' computation.

    `update` is `add` then `share` done incrementally (the engine's path); `add` and `share` remain for
    callers that hold their own previous bits (`bits`, the dense (N, B) table), and reset the incremental state.
    """

    _storages: ClassVar[dict[bool, type[SwarmKnowledge]]] = {}  # dense? -> its storage (each registers itself)

    def __init_subclass__(cls, dense: bool, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        SwarmKnowledge._storages[dense] = cls

    def __new__(cls, samples: Array, start: Ints, count: Ints, n_agents: int,
                dense: bool | None = None) -> SwarmKnowledge:
        if cls is SwarmKnowledge:
            if dense is None:
                dense = n_agents * int(((count + 7) // 8).sum()) <= DENSE_MAX_BYTES
            cls = SwarmKnowledge._storages[dense]
        return super().__new__(cls)

    def __init__(self, samples: Array, start: Ints, count: Ints, n_agents: int, dense: bool | None = None):
        self.samples = samples
        self.start, self.count = start, count
        m = count.size
        self.n = n_agents
        self.nbytes = ((count + 7) // 8).astype(np.int64)  # (M,) bytes of each obstacle's block
        self.b0 = np.concatenate([[0], np.cumsum(self.nbytes)[:-1]]).astype(np.int64) if m else self.nbytes
        self.b1 = self.b0 + self.nbytes  # (the dense layout: obstacle l's block at bytes b0[l]:b1[l])
        self._cache: dict[tuple[int, bytes], Array] = {}
        self._last: dict[tuple[int, int], tuple[NDArray[np.uint8], Array]] = {}  # (i, l) -> last (block, hull)
        # OR of every agent's bits, dense layout (only sensing adds to it: sharing moves bits between agents). (B,)
        self.union = np.zeros(int(self.b1[-1]) if m else 0, dtype=np.uint8)
        self.union_prev = self.union.copy()  # the union before the last update (B,)
        self._link_keys: Ints | None = None  # sorted i * N + j of the last update's links
        self._any_known = False  # whether union has any bit
        self.known = np.zeros((n_agents, m), dtype=bool)  # (N, M) knows(l) for every l
        self._hull_at = np.full((n_agents, m), None, dtype=object)  # (N, M) hull(i, l), None: stale
        self.version = 0  # bumped whenever any agent's knowledge (so any hull) may have changed

    # ------------------------------------------------------------------ what each storage provides

    @property
    def bits(self) -> NDArray[np.uint8]:
        """The dense table (N, B): every agent's bits of every obstacle."""
        raise NotImplementedError

    def add(self, agents: Ints, samples: Ints) -> None:
        """Mark sensed samples: agent index (Q,), global sample index (Q,)."""
        raise NotImplementedError

    def share(self, prev: NDArray[np.uint8], pairs: Ints) -> None:
        """OR into each agent what its linked neighbours knew at the previous tick.

        prev (N, B) the dense bits at k-1 (`bits`); pairs (E, 2) the linked pairs (i < j) at tick k.
        """
        raise NotImplementedError

    def update(self, agents: Ints, samples: Ints, links: Ints) -> None:
        """`add(agents, samples)` then `share(prev, links)` with prev the bits before this call.

        Same result, computed over what can change: over a link that already existed at the previous
        update, the previous update passed on everything but the byte columns that changed during it, so
        only those are shared again; a new link shares every column anyone knew. links (E, 2), i < j.
        """
        raise NotImplementedError

    def knows_rows(self, l: int, rows: Ints) -> NDArray[np.bool_]:
        """knows(l)[rows]: whether these agents know any of obstacle l. rows (R,) -> (R,)"""
        raise NotImplementedError

    def block(self, i: int, l: int) -> NDArray[np.uint8]:
        """Agent i's bits of obstacle l (its block; zeros if it holds none)."""
        raise NotImplementedError

    # ------------------------------------------------------------------------------ shared steps

    def _new_links(self, links: Ints) -> NDArray[np.bool_] | None:
        """Which links did not exist at the previous update (None: the same links). Remembers these."""
        keys = links[:, 0] * self.n + links[:, 1]  # (E,) increasing
        last = self._link_keys
        new: NDArray[np.bool_] | None
        if last is not None and last.shape == keys.shape and last.tobytes() == keys.tobytes():
            new = None  # the same links as last time (the common case)
        elif last is None or last.size == 0:
            new = np.ones(keys.shape[0], dtype=bool)
        else:
            at = np.minimum(np.searchsorted(last, keys), last.size - 1)
            new = last[at] != keys
        self._link_keys = keys if new is None or bool((keys[1:] >= keys[:-1]).all()) else np.sort(keys)
        return new

    def _reset(self) -> None:
        """After add or share: every incremental shortcut starts over."""
        self._link_keys = None
        self._hull_at[:] = None
        self.version += 1
        for l in range(self.count.size):
            self.known[:, l] = self.knows(l)

    # ---------------------------------------------------------------------------------- reading

    def knows(self, l: int) -> NDArray[np.bool_]:
        """(N,) whether each agent knows any of obstacle l."""
        return self.knows_rows(l, np.arange(self.n, dtype=np.int64))

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
