"""Range-limited sensing and ground-truth distances to the obstacles. Pure and batched.

Each obstacle's contour is sampled once, vertices included, at <= 1 m spacing; an agent senses every
contour point within R_v of its head point, labelled with the obstacle id (Assumption 2.1: the red
crosses of the paper's Fig. 1). No occlusion is modelled.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import SAMPLE_SPACING_M, Edges, norm2, sample_boundary, signed_distance, tile_edges
from reconswarm.scenario.model import Scenario

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ContourField:
    ids: tuple[str, ...]  # obstacle ids, sorted (the canonical obstacle order everywhere)
    polygons: tuple[Array, ...]  # (V_l, 2) each, CCW
    samples: Array  # (S, 2) contour points of every obstacle, block by block
    start: NDArray[np.int64]  # (M,) first sample of each obstacle
    count: NDArray[np.int64]  # (M,) samples of each obstacle
    owner: NDArray[np.int64]  # (S,) obstacle index of each sample
    edges: Edges  # the true polygons, for ground-truth distances
    centre: Array  # (M, 2) centre of each polygon's bounding circle
    reach: Array  # (M,) its radius
    _tiled: dict[int, Edges] = field(default_factory=dict, compare=False, repr=False)
    _idx: dict[bytes, tuple[NDArray[np.int64], Array, Array]] = field(default_factory=dict, compare=False, repr=False)
    _one: dict[int, Edges] = field(default_factory=dict, compare=False, repr=False)  # _edges_of one column
    _planes: list[Array] = field(default_factory=list, compare=False, repr=False)  # see _derived

    @staticmethod
    def from_scenario(s: Scenario, spacing_m: float = SAMPLE_SPACING_M) -> ContourField:
        polys = tuple(s.polygon(k) for k in range(len(s.obstacles)))
        blocks = [sample_boundary(poly, spacing_m) for poly in polys]
        count = np.array([b.shape[0] for b in blocks], dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64) if blocks else count
        samples = np.concatenate(blocks) if blocks else np.zeros((0, 2))
        owner = np.repeat(np.arange(len(blocks)), count).astype(np.int64)
        centre = np.array([poly.mean(axis=0) for poly in polys]).reshape(-1, 2)
        reach = np.array([float(norm2(poly - c).max()) for poly, c in zip(polys, centre, strict=True)])
        return ContourField(tuple(o.id for o in s.obstacles), polys, samples, start, count, owner,
                            Edges.of(list(polys)), centre, reach)

    def _derived(self) -> list[Array]:
        """Derived once: the bounding circles' centres as contiguous x and y arrays (M,) each, and (M,) the
        distance from an obstacle's boundary beyond which a point is outside it (its bounding circle's
        radius, with a margin for rounding)."""
        if not self._planes:
            self._planes.extend((np.ascontiguousarray(self.centre[:, 0]), np.ascontiguousarray(self.centre[:, 1]),
                                 self.reach * (1 + 1e-9) + 1e-9))
        return self._planes

    @property
    def n_obstacles(self) -> int:
        return len(self.ids)

    def true_distances(self, p: Array, exact_within_m: float = np.inf, radii: Array | None = None) -> Array:
        """Signed distance from every head point to every obstacle: p (N, 2) -> d (N, M).

        Exact wherever the distance is <= exact_within_m; beyond, possibly a lower bound from the
        obstacle's bounding circle (still > exact_within_m), which saves the work for far-away obstacles.
        With radii (N,), also exact for the pair(s) that hold the minimum of d - radii (the smallest
        surface gap): a pair is left at its lower bound only if that bound cannot hold the minimum.
        """
        n, m = p.shape[0], self.n_obstacles
        if m == 0:
            return np.zeros((n, 0))
        if np.isinf(exact_within_m) or n * m <= 256:  # small: exact everywhere is cheaper than picking
            return self._exact_all(p)
        bound = self._bounds(p)  # (N, M)
        close = bound <= exact_within_m
        if radii is None:
            if not close.any():
                return bound
            return self._exact_all(p)
        gap = bound - radii[:, None]
        out = bound  # (fresh: filled in place from here on)
        if not close.any():  # all far: exact for the pair(s) that can hold the minimum gap, bounds elsewhere
            gap_t = gap.T  # (M, N), contiguous: the same entries read row by row
            i, j = _first_min(gap_t, m)
            out[i, j] = float(self._exact(p, np.array([i]), np.array([j]))[0])
            below_t = gap_t < out[i, j] - radii[i]
            below_t[j, i] = False  # exact already
            cols, rows = below_t.nonzero()
            if rows.size:
                out[rows, cols] = self._exact(p, rows, cols)
            return out
        rows, cols = np.nonzero(close)
        out[rows, cols] = self._exact(p, rows, cols)
        gap = out - radii[:, None]  # exact where close, a lower bound elsewhere
        rows, cols = np.nonzero(~close & (gap < gap[close].min()))
        if rows.size:
            out[rows, cols] = self._exact(p, rows, cols)
        return out

    def _bounds(self, p: Array) -> Array:
        """norm2(p[:, None, :] - centre[None, :, :]) - reach: (N, 2) -> (N, M), the same operations element by
        element, one obstacle at a time over contiguous (N,) rows (several times faster than the (N, M)
        broadcast at 100,000 agents: each pass stays in cache). The result is the transpose of an (M, N)
        array (column-major): equal values, a different memory layout."""
        cx, cy, _ = self._derived()
        n = p.shape[0]
        out = np.empty((self.n_obstacles, n))
        x, y = np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1])
        u = np.empty(n)
        for m in range(self.n_obstacles):
            t = out[m]
            np.subtract(x, cx[m], out=t)
            t *= t
            np.subtract(y, cy[m], out=u)
            u *= u
            t += u
            np.sqrt(t, out=t)
            t -= self.reach[m]
        return out.T

    def _exact_all(self, p: Array) -> Array:
        """Exact signed distance from every head point to every obstacle: (N, 2) -> (N, M)."""
        n = p.shape[0]
        tiled = self._tiled.get(n)
        if tiled is None:
            tiled = self._tiled[n] = tile_edges(self.edges, n)
        return signed_distance(p[:, 0:1], p[:, 1:2], tiled, normals=False, outside_beyond=self._derived()[2])

    def _exact(self, p: Array, rows: NDArray[np.int64], cols: NDArray[np.int64]) -> Array:
        """Signed distance of head point rows[q] to obstacle cols[q]: (Q,), (Q,) -> (Q,).

        The same edges (padded alike) and element-wise arithmetic as the tiled call in true_distances.
        """
        return signed_distance(p[rows, 0], p[rows, 1], self._edges_of(cols), normals=False,
                               outside_beyond=self._derived()[2][cols])

    def _edges_of(self, cols: NDArray[np.int64]) -> Edges:
        """The true polygons' edges for the given obstacle columns, one row each: (Q,) -> Edges (Q, V)."""
        one = cols.size == 1
        if one and (got := self._one.get(int(cols[0]))) is not None:
            return got
        e = self.edges
        out = Edges(e.ax[cols], e.ay[cols], e.abx[cols], e.aby[cols], e.inv_den[cols], e.pad[cols],
                    e.invalid[cols], e.closed[cols])
        if one:
            self._one[int(cols[0])] = out
        return out

    def scan(self, p: Array, sensing_range_m: float, true_d: Array) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Contour points within R_v of each head point.

        p (N, 2), true_d (N, M) from true_distances -> (agent index (Q,), sample index (Q,)), sorted by
        agent then sample.
        """
        empty = np.zeros(0, dtype=np.int64)
        if self.n_obstacles == 0:
            return empty, empty
        hit = true_d <= sensing_range_m  # (N, M)
        seen = cast("NDArray[np.bool_]", hit.any(axis=0)).nonzero()[0]
        if seen.size == 0:
            return empty, empty
        near = cast("NDArray[np.bool_]", hit[:, seen].any(axis=1)).nonzero()[0]  # (n,) agents near any of them
        idx, sx, sy = self._sample_index(seen)  # (S',) increasing, and the samples' coordinates
        if seen.size > 1 and near.size * idx.size > 4096:
            return self._scan_each(p, sensing_range_m, hit, seen)
        # norm2(p[near, None] - samples[idx][None]), on contiguous coordinate planes: (n, S')
        dx = p[near, 0:1] - sx
        dy = p[near, 1:2] - sy
        ok = np.sqrt(dx * dx + dy * dy) <= sensing_range_m
        if seen.size > 1:  # an obstacle's samples count only for agents within range of that obstacle
            ok &= hit[near][:, self.owner[idx]]
        a, s = np.nonzero(ok)  # row-major: sorted by agent, then sample
        return near[a], idx[s]

    def _scan_each(self, p: Array, sensing_range_m: float, hit: NDArray[np.bool_],
                   seen: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """scan, obstacle by obstacle (many agents near several obstacles)."""
        agents, samples = [], []
        for m in seen.tolist():
            near = hit[:, m].nonzero()[0]
            idx, sx, sy = self._sample_index(seen[seen == m])  # obstacle m's samples (S_l,)
            dx = p[near, 0:1] - sx  # (n, S_l), norm2 on contiguous coordinate planes
            dy = p[near, 1:2] - sy
            a, s = np.nonzero(np.sqrt(dx * dx + dy * dy) <= sensing_range_m)
            agents.append(near[a])
            samples.append(idx[s])
        total = self.samples.shape[0]
        keys = np.concatenate(agents).astype(np.int64) * total + np.concatenate(samples)  # (Q,) distinct
        keys.sort()  # by agent, then sample
        a_all, s_all = np.divmod(keys, total)
        return a_all, s_all

    def _sample_index(self, seen: NDArray[np.int64]) -> tuple[NDArray[np.int64], Array, Array]:
        """Global indices (increasing) and x, y of the samples of obstacles `seen`. (K,) -> 3 x (S',)"""
        key = seen.tobytes()
        got = self._idx.get(key)
        if got is None:
            idx = np.concatenate([np.arange(self.start[m], self.start[m] + self.count[m]) for m in seen.tolist()])
            idx = idx.astype(np.int64)
            if len(self._idx) > 4096:
                self._idx.clear()
            got = self._idx[key] = (idx, self.samples[idx, 0].copy(), self.samples[idx, 1].copy())
        return got


def _first_min(gap_t: Array, m: int) -> tuple[int, int]:
    """divmod(gap.argmin(), m) of gap = gap_t.T (N, M) without reordering gap_t: the (i, j) of the smallest
    entry, the first in gap's row-major order among equal ones (or the first NaN, as argmin)."""
    at = gap_t.argmin(axis=1)  # (M,) each obstacle's first smallest (or first NaN), one contiguous pass each
    low = gap_t[np.arange(gap_t.shape[0]), at]  # (M,)
    v = low.min()
    if np.isnan(v):
        return divmod(int(np.ascontiguousarray(gap_t.T).argmin()), m)
    js = (low == v).nonzero()[0]
    first = int(np.argmin(at[js] * m + js))
    return int(at[js[first]]), int(js[first])
