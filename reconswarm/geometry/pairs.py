"""Index pairs of nearby points: every pair within a radius, exactly, and a Verlet list of them for points
that move a little between calls. Pure numpy.

Small sets are searched densely (all pairs); large ones on a uniform grid of cells at least one radius
wide, so that a pair within the radius lies in the same cell or in two adjacent ones. Both paths keep a
pair by the same test, norm2 distance <= radius, so they give the same set; it comes sorted by (i, j).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import norm2, rows_where

Array = NDArray[np.float64]

DENSE_MAX = 96  # up to this many points, every pair is measured
_GRID_CELLS_MAX = 2**30  # cells per axis at most (the cell keys stay far inside int64)
# Cells of the grid compared with a point's own: itself and four of the eight around it, so that each
# unordered pair of adjacent cells is visited once.
_FORWARD = ((0, 1), (1, -1), (1, 0), (1, 1))
_TRIU: dict[int, NDArray[np.int64]] = {}
_NONE = np.zeros(0, dtype=np.int64)


def _triu(n: int) -> NDArray[np.int64]:
    pairs = _TRIU.get(n)
    if pairs is None:
        ii, jj = np.triu_indices(n, 1)
        pairs = np.stack([ii, jj], axis=1).astype(np.int64)
        if len(_TRIU) > 64:
            _TRIU.clear()
        _TRIU[n] = pairs
    return pairs


def pairs_within(points: Array, radius: float) -> NDArray[np.int64]:
    """Index pairs (i < j) with ‖p_i - p_j‖ <= radius, sorted. (N, 2) -> (E, 2).

    Dense for small N, a grid for large N; both filter with norm2 so the set is the same.
    """
    return pairs_and_distances(points, radius)[0]


def pairs_and_distances(points: Array, radius: float) -> tuple[NDArray[np.int64], Array]:
    """pairs_within, and the norm2 distance of each pair: (N, 2) -> pairs (E, 2), d (E,)."""
    n = points.shape[0]
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    if n <= DENSE_MAX:
        cand = _triu(n)
        d = norm2(points[cand[:, 0]] - points[cand[:, 1]])
        keep = d <= radius
        return rows_where(cand, keep), d[keep]  # already sorted
    i, j = grid_candidates(points, radius)  # (C,) each pair once, i < j
    x, y = points[:, 0], points[:, 1]
    dx = x.take(i) - x.take(j)  # norm2(points[i] - points[j]), coordinate by coordinate
    dy = y.take(i) - y.take(j)
    d = np.sqrt(dx * dx + dy * dy)
    within = (d <= radius).nonzero()[0]
    i, j, d = i.take(within), j.take(within), d.take(within)
    order = np.argsort(i * n + j)  # by (i, j), without a row-wise sort (keys are distinct)
    out = np.empty((order.size, 2), dtype=np.int64)  # (E, 2)
    out[:, 0] = i.take(order)
    out[:, 1] = j.take(order)
    return out, d.take(order)


def grid_candidates(points: Array, radius: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Every pair (i < j, unsorted, each once) of points in the same or adjacent cells of a grid whose
    cells are wider than radius: a superset of the pairs within radius. Points that are not finite are in
    no pair. (N, 2) -> i (C,), j (C,)"""
    n = points.shape[0]
    fin = np.isfinite(points[:, 0]) & np.isfinite(points[:, 1])
    if not fin.all():
        idx = np.flatnonzero(fin)
        if idx.size < 2:
            return _NONE, _NONE
        a, b = grid_candidates(points[idx], radius)
        return idx[a], idx[b]
    x, y = points[:, 0], points[:, 1]
    x0, y0 = float(x.min()), float(y.min())
    span = max(float(x.max()) - x0, float(y.max()) - y0)
    # Wider than radius by a relative 1e-9 (rounding in the cell division cannot matter), and coarse
    # enough that the keys fit: a wider cell only adds candidates.
    h = max(radius * (1 + 1e-9) + 1e-9, span / _GRID_CELLS_MAX)
    cx = np.floor((x - x0) / h).astype(np.int64)
    cy = np.floor((y - y0) / h).astype(np.int64)
    w = int(cy.max()) + 2  # row w - 1 of every column is empty: cy ± 1 never reaches another column's cell
    cell = cx * w + cy
    order = np.argsort(cell, kind="stable")
    sc = cell[order]  # (N,) sorted
    pos = np.arange(n)
    los = [pos + 1]  # the same cell: the points after this one
    his = [np.searchsorted(sc, sc, side="right")]
    for dx, dy in _FORWARD:
        t = sc + (dx * w + dy)
        los.append(np.searchsorted(sc, t, side="left"))
        his.append(np.searchsorted(sc, t, side="right"))
    lo = np.concatenate(los)  # (5N,) a range of sorted positions per point and cell
    counts = np.concatenate(his) - lo
    total = int(counts.sum())
    if total == 0:
        return _NONE, _NONE
    src = np.repeat(np.tile(pos, len(los)), counts)  # (C,) sorted position of the first point
    first = np.cumsum(counts) - counts  # where each range starts in the output
    dst = np.repeat(lo - first, counts) + np.arange(total)  # (C,) sorted position of the second
    i, j = order.take(src), order.take(dst)
    return np.minimum(i, j), np.maximum(i, j)


class NearPairs:
    """pairs_and_distances(points, radius) for a point set that moves a little every call (a Verlet list).

    Large sets: the pairs within radius + skin are found once (grid, sorted) and reused while no point
    has moved more than skin / 2 since; each call then only measures those candidates. A pair within
    radius now was within radius + skin then, so the result is the same pairs in the same order with the
    same norm2 distances as pairs_and_distances. Small sets (dense search) go straight through.
    """

    def __init__(self, radius: float, skin: float) -> None:
        self.radius, self.skin = radius, skin
        self._ref = np.zeros((0, 2))
        self._cand = np.zeros((0, 2), dtype=np.int64)
        self._i = self._j = np.zeros(0, dtype=np.int64)

    def __call__(self, points: Array) -> tuple[NDArray[np.int64], Array]:
        if points.shape[0] <= DENSE_MAX:
            return pairs_and_distances(points, self.radius)
        if self._ref.shape != points.shape or 2 * float(norm2(points - self._ref).max()) > self.skin - 1e-6:
            self._cand = pairs_and_distances(points, self.radius + self.skin)[0]
            self._i, self._j = self._cand[:, 0].copy(), self._cand[:, 1].copy()
            self._ref = points.copy()
        x, y = points[:, 0], points[:, 1]
        dx = x.take(self._i) - x.take(self._j)  # norm2(points[i] - points[j]), coordinate by coordinate
        dy = y.take(self._i) - y.take(self._j)
        d = np.sqrt(dx * dx + dy * dy)
        at = (d <= self.radius).nonzero()[0]
        return self._cand.take(at, axis=0), d.take(at)
