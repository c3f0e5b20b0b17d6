"""The swarm graph and its split / merge events (docs/paper.md). Pure; used live by the in-process
engine and by the monitor process.

Edge i–j: the pair is linked (reconswarm.paper.link, with hysteresis): it forms when ‖p_i - p_j‖ <= link_range
and, once made, breaks only beyond link_range + 2 m.
Groups are the connected components over active agents. A change of the grouping is recorded once the
new grouping has held for 1 s of simulated time: a group dividing is a *split*, groups joining a
*merge*, each with the groups before and after (agent ids), timed when the change happened.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.pairs import pairs_within
from reconswarm.geometry.plane import norm2, rows_where
from reconswarm.paper.link import HYSTERESIS_M, linked

PERSISTENCE_S = 1.0

Array = NDArray[np.float64]
Groups = tuple[frozenset[int], ...]


def graph_edges(p: Array, active: NDArray[np.bool_], prev: NDArray[np.int64], link_m: float,
                hysteresis_m: float = HYSTERESIS_M, cand: NDArray[np.int64] | None = None,
                cand_d: Array | None = None, prev_keys: NDArray[np.int64] | None = None) -> NDArray[np.int64]:
    """Edges (E, 2) (i < j, agent indices) of the swarm graph at this tick.

    p (N, 2), active (N,), prev (E', 2) the edges of the previous tick; cand (C, 2) optional candidate
    pairs that include every pair within link_m + hysteresis_m, and cand_d (C,) optionally their norm2
    distances; prev_keys (E',) optionally prev's i * N + j, sorted.
    """
    n = p.shape[0]
    if cand is None:
        cand = pairs_within(p, link_m + hysteresis_m)
        cand_d = None
    if cand.shape[0] == 0:
        return cand
    if cand_d is None:
        cand_d = norm2(p[cand[:, 0]] - p[cand[:, 1]])
    if not active.all():
        live = active[cand[:, 0]] & active[cand[:, 1]]
        cand, cand_d = rows_where(cand, live), cand_d[live]
    keep = linked(cand_d, link_m)
    band = (~keep & (cand_d <= link_m + hysteresis_m)).nonzero()[0]  # linked only if linked before
    if band.size and prev.shape[0]:
        keys = cand[band, 0] * n + cand[band, 1]
        old = prev_keys if prev_keys is not None else np.unique(prev[:, 0] * n + prev[:, 1])
        keep[band] = linked(cand_d[band], link_m, _member(keys, old), hysteresis_m)
    return rows_where(cand, keep)


def labels(n: int, edges: NDArray[np.int64], active: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Component label per agent: the smallest agent index of its group; -1 if inactive. -> (N,)

    Union-find in whole-array steps: every edge hooks both ends to the smaller of their labels, then
    labels jump to their label's label, until every edge joins equal labels. Labels only decrease and
    always name an agent of the same component, so at the fixed point each component carries its
    smallest index.
    """
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    lab = np.arange(n, dtype=np.int64)
    if edges.shape[0]:
        a, b = edges[:, 0], edges[:, 1]
        while True:
            la, lb = lab[a], lab[b]
            differ = la != lb
            if not differ.any():
                break
            low = np.minimum(la, lb)[differ]
            np.minimum.at(lab, la[differ], low)  # hook the larger root under the smaller label
            np.minimum.at(lab, lb[differ], low)
            np.minimum.at(lab, a[differ], low)
            np.minimum.at(lab, b[differ], low)
            while True:  # pointer jumping: every label to its root
                up = lab[lab]
                if np.array_equal(up, lab):
                    break
                lab = up
    return np.where(active, lab, -1)


def groups_of(lab: NDArray[np.int64], ids: NDArray[np.int64]) -> Groups:
    """Partition as frozensets of agent ids, ordered by their smallest member."""
    out: dict[int, list[int]] = {}
    for idx in np.flatnonzero(lab >= 0):
        out.setdefault(int(lab[idx]), []).append(int(ids[idx]))
    return tuple(frozenset(v) for _, v in sorted(out.items()))


def _sorted_groups(gs: list[frozenset[int]] | Groups) -> list[list[int]]:
    return sorted((sorted(g) for g in gs), key=lambda g: g[0])


def diff(old: Groups, new: Groups) -> list[tuple[str, list[list[int]], list[list[int]]]]:
    """Splits and merges turning partition `old` into `new`, over the agents present in both.

    Returns (kind, before, after) triples. A many-to-many change is a split into the intersections
    followed by a merge of them.
    """
    common = frozenset().union(*old) & frozenset().union(*new) if old and new else frozenset()
    o = [g & common for g in old if g & common]
    nw = [g & common for g in new if g & common]
    # Overlap components between old and new groups.
    out: list[tuple[str, list[list[int]], list[list[int]]]] = []
    seen_o: set[int] = set()
    for a in range(len(o)):
        if a in seen_o:
            continue
        olds, news = {a}, set()
        frontier = [("o", a)]
        while frontier:
            side, k = frontier.pop()
            if side == "o":
                for b, g in enumerate(nw):
                    if b not in news and g & o[k]:
                        news.add(b)
                        frontier.append(("n", b))
            else:
                for b, g in enumerate(o):
                    if b not in olds and g & nw[k]:
                        olds.add(b)
                        frontier.append(("o", b))
        seen_o |= olds
        before = [o[k] for k in olds]
        after = [nw[k] for k in news]
        if len(before) == 1 and len(after) > 1:
            out.append(("split", _sorted_groups(before), _sorted_groups(after)))
        elif len(before) > 1 and len(after) == 1:
            out.append(("merge", _sorted_groups(before), _sorted_groups(after)))
        elif len(before) > 1 and len(after) > 1:
            middle = [x & y for x in before for y in after if x & y]
            for x in before:
                parts = [m for m in middle if m <= x]
                if len(parts) > 1:
                    out.append(("split", _sorted_groups([x]), _sorted_groups(parts)))
            for y in after:
                parts = [m for m in middle if m <= y]
                if len(parts) > 1:
                    out.append(("merge", _sorted_groups(parts), _sorted_groups([y])))
    return out


def _sorted_keys(edges: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """i * n + j of edges (E, 2), sorted. -> (E,)"""
    keys = edges[:, 0] * n + edges[:, 1]
    return keys if bool((keys[1:] > keys[:-1]).all()) else np.unique(keys)


def _member(keys: NDArray[np.int64], sorted_keys: NDArray[np.int64]) -> NDArray[np.bool_]:
    """np.isin(keys, sorted_keys) for a sorted right-hand side."""
    if sorted_keys.size == 0:
        return np.zeros(keys.shape[0], dtype=bool)
    at = np.minimum(np.searchsorted(sorted_keys, keys), sorted_keys.size - 1)
    return sorted_keys[at] == keys


def _changes(old: NDArray[np.int64], new: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Keys in new and not in old (added), in old and not in new (removed), both sorted; old and new sorted
    and unique. One merge of the two sorted runs (a stable sort of their concatenation) finds both."""
    cat = np.concatenate([old, new])
    order = np.argsort(cat, kind="stable")
    merged = cat[order]
    same = merged[1:] == merged[:-1]  # a key in both: two neighbours in the merge
    single = np.ones(merged.size, dtype=bool)
    single[1:] &= ~same
    single[:-1] &= ~same
    from_new = order >= old.size
    return merged[single & from_new], merged[single & ~from_new]


MAX_CERTIFIED = 16  # removed edges checked one by one before a full recomputation is cheaper


def _same_components(lab: NDArray[np.int64], edges: NDArray[np.int64], keys: NDArray[np.int64],
                     old_keys: NDArray[np.int64], n: int) -> bool:
    """True when the graph `edges` (keys sorted) provably has the components `lab` of the old graph.

    Sufficient: every added edge joins two agents of one old group (no merge), and the two ends of every
    removed edge still share a neighbour (no split). False means: recompute.
    """
    added, removed = _changes(old_keys, keys)
    if added.size and not bool((lab[added // n] == lab[added % n]).all()):
        return False
    if removed.size > MAX_CERTIFIED:
        return False
    if removed.size:
        a, b = np.divmod(removed, n)  # (R,) the ends of each removed edge
        ends = np.zeros(n, dtype=bool)
        ends[a] = True
        ends[b] = True
        touching = rows_where(edges, ends[edges[:, 0]] | ends[edges[:, 1]])  # the only edges that can matter
        x, y = touching[:, 0], touching[:, 1]  # (E',)

        def adjacent(v: NDArray[np.int64]) -> NDArray[np.bool_]:
            """(R, N): whether agent c is a neighbour of v[r] in the new graph."""
            adj = np.zeros((v.size, n), dtype=bool)
            r, e = (x[None, :] == v[:, None]).nonzero()
            adj[r, y[e]] = True
            r, e = (y[None, :] == v[:, None]).nonzero()
            adj[r, x[e]] = True
            return adj

        if not bool((adjacent(a) & adjacent(b)).any(axis=1).all()):
            return False
    return True


@dataclass
class TopologyTracker:
    """Follows the swarm graph tick by tick and emits confirmed split / merge events."""

    ids: NDArray[np.int64]  # (N,) agent ids in index order
    link_m: float
    hysteresis_m: float = HYSTERESIS_M
    persistence_s: float = PERSISTENCE_S
    edges: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    confirmed: Groups | None = None
    pending: Groups | None = None
    pending_since: float = 0.0
    current: Groups = ()
    _labels: NDArray[np.int64] | None = None
    _keys: NDArray[np.int64] | None = None  # i * N + j of self.edges (sorted), for the next tick
    _keys_n: int = 0
    _active_bytes: bytes = b""

    def step(self, t: float, p: Array, active: NDArray[np.bool_], cand: NDArray[np.int64] | None = None,
             cand_d: Array | None = None) -> list[dict[str, Any]]:
        """Feed the positions at time t; returns the events confirmed at this tick.

        cand: optional superset (C, 2) of the pairs within link + hysteresis, cand_d (C,) optionally their
        norm2 distances.
        """
        prev_edges = self.edges
        n = p.shape[0]
        if self._keys is None or self._keys_n != n:
            self._keys, self._keys_n = _sorted_keys(prev_edges, n), n
        old_keys = self._keys
        edges = graph_edges(p, active, prev_edges, self.link_m, self.hysteresis_m, cand, cand_d, old_keys)
        self.edges = edges
        same_active = self._labels is not None and active.tobytes() == self._active_bytes
        if edges.shape == prev_edges.shape and edges.tobytes() == prev_edges.tobytes():
            keys = old_keys  # the same edges (the common case)
        else:
            self._keys = keys = _sorted_keys(edges, n)
        if same_active and keys is old_keys:
            pass  # the same graph: the same groups
        elif same_active and self._labels is not None and _same_components(self._labels, edges, keys, old_keys, n):
            pass
        else:
            lab = labels(p.shape[0], self.edges, active)
            if self._labels is None or not np.array_equal(lab, self._labels):
                self.current = groups_of(lab, self.ids)
            self._labels = lab
            self._active_bytes = (lab >= 0).tobytes()  # which agents the labels cover
        if self.confirmed is None:
            self.confirmed = self.current
            return []
        if self.current == self.confirmed:
            self.pending = None
            return []
        if self.pending != self.current:
            self.pending, self.pending_since = self.current, t
        if t - self.pending_since < self.persistence_s - 1e-9:
            return []
        events = [{"t": round(self.pending_since, 9), "kind": kind, "before": before, "after": after,
                   "t_confirmed": round(t, 9)}
                  for kind, before, after in diff(self.confirmed, self.current)]
        self.confirmed, self.pending = self.current, None
        return events

    @property
    def n_groups(self) -> int:
        return len(self.current)
