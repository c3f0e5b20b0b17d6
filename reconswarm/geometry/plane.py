"""Planar geometry shared by every part of reconswarm: pure numpy, no zenoh, no I/O.

Conventions: points are float64 arrays of shape (..., 2); polygons are (V, 2) vertex arrays in
counter-clockwise order. Every function here is deterministic element by element, so calling it with
one agent's rows gives bit-identical results to calling it with the whole swarm (the distributed and
in-process modes rely on that).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

# Relative tolerance under which three points count as collinear when building a hull. Points sampled
# along a straight edge deviate from it by rounding only (~1e-16 relative), so they are dropped
# consistently whatever else is in the input; real corners are many orders of magnitude above this.
COLLINEAR_TOL = 1e-9
SAMPLE_SPACING_M = 1.0  # obstacle contours are sampled at most this far apart (what agents sense)
ON_EDGE_M = 1e-9  # closer to an edge than this, a point's direction from it is the edge's normal


def rows_where(a: NDArray[Any], mask: NDArray[np.bool_]) -> NDArray[Any]:
    """a[mask] for a 2-D array a (R, C) and a row mask (R,): the same rows, gathered by index (several times
    faster than numpy's boolean indexing of a 2-D array, and no slower for a few rows). -> (R', C)"""
    return a.take(mask.nonzero()[0], axis=0)


def norm2(v: Array) -> Array:
    """Euclidean norm over the last axis, written out so that it is reproducible bit for bit.

    (..., 2) -> (...)
    """
    x = v[..., 0]
    y = v[..., 1]
    return np.sqrt(x * x + y * y)


def _cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _turns_left(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> bool:
    """True when o -> a -> b is a strict left turn beyond the collinearity tolerance."""
    ax, ay = a[0] - o[0], a[1] - o[1]
    bx, by = b[0] - o[0], b[1] - o[1]
    scale = math.sqrt((ax * ax + ay * ay) * (bx * bx + by * by))
    return (ax * by - ay * bx) > COLLINEAR_TOL * scale


def convex_hull(points: Array) -> Array:
    """Canonical convex hull: (P, 2) -> (V, 2), counter-clockwise, starting at the lowest (x, y).

    Collinear and duplicate points are dropped, so the same point *set* (or any superset that adds only
    points inside or on the hull) always gives the same array. Degenerate inputs give 1 or 2 vertices.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] == 0:
        return np.zeros((0, 2))
    order = np.lexsort((pts[:, 1], pts[:, 0]))
    pts = pts[order]
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.any(pts[1:] != pts[:-1], axis=1)
    pts = rows_where(pts, keep)
    if len(pts) <= 2:
        return pts.copy()
    xs: list[float] = pts[:, 0].tolist()
    ys: list[float] = pts[:, 1].tolist()
    lower = _chain(xs, ys, range(len(xs)))
    upper = _chain(xs, ys, range(len(xs) - 1, -1, -1))
    hull = lower[:-1] + upper[:-1]
    if len(hull) < 2:  # all points collinear: the hull is the segment between the extremes
        hull = [0, len(xs) - 1]
    return pts[hull]


def _chain(xs: list[float], ys: list[float], order: range) -> list[int]:
    """One monotone chain of Andrew's algorithm over points in `order`: indices of its vertices.

    `_turns_left` written inline (the same operations in the same order): this loop is the hull's cost.
    """
    out: list[int] = []
    tol = COLLINEAR_TOL
    sqrt = math.sqrt
    for q in order:
        qx, qy = xs[q], ys[q]
        while len(out) >= 2:
            o, a = out[-2], out[-1]
            ox, oy = xs[o], ys[o]
            ax, ay = xs[a] - ox, ys[a] - oy
            bx, by = qx - ox, qy - oy
            if (ax * by - ay * bx) > tol * sqrt((ax * ax + ay * ay) * (bx * bx + by * by)):
                break
            out.pop()
        out.append(q)
    return out


def points_inside_hull(points: Array, hull: Array) -> NDArray[np.bool_]:
    """Which points lie inside or on a convex CCW polygon (>= 3 vertices). (P, 2), (V, 2) -> (P,)"""
    if hull.shape[0] < 3:
        return np.zeros(points.shape[0], dtype=bool)
    a = hull
    ab = np.concatenate((hull[1:], hull[:1])) - a  # (V, 2): each vertex to the next
    ap = points[:, None, :] - a[None, :, :]  # (P, V, 2)
    cross = ab[None, :, 0] * ap[..., 1] - ab[None, :, 1] * ap[..., 0]
    return np.all(cross >= 0.0, axis=1)


def merge_hull(hull: Array, points: Array) -> Array:
    """Hull of an existing canonical hull plus new points: (V, 2), (P, 2) -> (V', 2)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] == 0:
        return hull
    if hull.shape[0] >= 3:
        pts = rows_where(pts, ~points_inside_hull(pts, hull))
        if pts.shape[0] == 0:
            return hull
    return convex_hull(np.concatenate([hull, pts]))


def polygon_area(vertices: Array) -> float:
    """Signed area (positive for counter-clockwise). (V, 2) -> float"""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def is_strictly_convex(vertices: Array) -> bool:
    """True for a simple polygon whose every turn is a strict left turn (CCW) or every one a right turn."""
    v = np.asarray(vertices, dtype=np.float64)
    n = v.shape[0]
    if n < 3:
        return False
    turns = [_cross(tuple(v[i - 1]), tuple(v[i]), tuple(v[(i + 1) % n])) for i in range(n)]
    if not (all(t > 0 for t in turns) or all(t < 0 for t in turns)):
        return False
    # Turning the same way at every vertex still allows a star that winds twice: total angle must be 2π.
    ang = 0.0
    for i in range(n):
        e1 = v[i] - v[i - 1]
        e2 = v[(i + 1) % n] - v[i]
        ang += math.atan2(e1[0] * e2[1] - e1[1] * e2[0], float(np.dot(e1, e2)))
    return abs(abs(ang) - 2 * math.pi) < 1e-6


def edge_sample_counts(vertices: Array, spacing_m: float = SAMPLE_SPACING_M) -> list[int]:
    """How many contour points `sample_boundary` puts on each edge (from vertex i, that vertex included).

    (V, 2) -> V counts; edge i of length L gets max(1, ceil(L / spacing_m)) points, L / count apart.
    """
    v = np.asarray(vertices, dtype=np.float64)
    return [max(1, math.ceil(float(norm2(v[(i + 1) % v.shape[0]] - v[i])) / spacing_m)) for i in range(v.shape[0])]


def sample_boundary(vertices: Array, spacing_m: float = SAMPLE_SPACING_M) -> Array:
    """Contour points along a closed polygon, vertices included, at most `spacing_m` apart.

    (V, 2) -> (S, 2), in boundary order.
    """
    v = np.asarray(vertices, dtype=np.float64)
    out = []
    for i, n in enumerate(edge_sample_counts(v, spacing_m)):
        a, b = v[i], v[(i + 1) % v.shape[0]]
        t = np.arange(n, dtype=np.float64)[:, None] / n
        out.append(a + t * (b - a))
    return np.concatenate(out)


@dataclass(frozen=True)
class Edges:
    """Precomputed polygon edges, padded: batch shape (K,) and V edge slots per polygon.

    A polygon of 1 vertex is a point, of 2 a segment; padding slots are never nearest.
    """

    ax: Array  # (K, V) edge start
    ay: Array
    abx: Array  # (K, V) edge vector
    aby: Array
    inv_den: Array  # (K, V) 1 / |ab|² (0 for a zero-length edge)
    pad: Array  # (K, V) 0 for a real edge, +inf for padding
    invalid: NDArray[np.bool_]  # (K, V) padding
    closed: NDArray[np.bool_]  # (K,) at least 3 vertices: has an inside

    @staticmethod
    def of(polys: list[Array]) -> Edges:
        """Edges of polygons (V_k, 2) each, in the given order."""
        k = len(polys)
        vmax = max([1, *(p.shape[0] for p in polys)])
        verts = np.zeros((k, vmax, 2))
        counts = np.zeros(k, dtype=np.int64)
        for i, p in enumerate(polys):
            verts[i, : p.shape[0]] = p
            counts[i] = p.shape[0]
        idx = np.arange(vmax)[None, :]
        nxt = (idx + 1) % np.maximum(counts, 1)[:, None]
        b = np.take_along_axis(verts, nxt[..., None], axis=1)
        ab = b - verts
        den = ab[..., 0] * ab[..., 0] + ab[..., 1] * ab[..., 1]
        invalid = idx >= counts[:, None]
        with np.errstate(divide="ignore"):
            inv_den = np.where(den > 0.0, 1.0 / np.where(den > 0.0, den, 1.0), 0.0)
        return Edges(verts[..., 0].copy(), verts[..., 1].copy(), ab[..., 0].copy(), ab[..., 1].copy(), inv_den,
                     np.where(invalid, np.inf, 0.0), invalid, counts >= 3)


def tile_edges(e: Edges, n: int) -> Edges:
    """The same polygons for n points each: batch (K,) -> (n, K), no broadcasting needed per call."""
    def rep(a: NDArray[Any]) -> NDArray[Any]:
        return np.ascontiguousarray(np.broadcast_to(a, (n, *a.shape)))

    return Edges(rep(e.ax), rep(e.ay), rep(e.abx), rep(e.aby), rep(e.inv_den), rep(e.pad), rep(e.invalid),
                 rep(e.closed))


@overload
def signed_distance(px: Array, py: Array, e: Edges) -> tuple[Array, Array, Array]: ...


@overload
def signed_distance(px: Array, py: Array, e: Edges, *, normals: Literal[True]) -> tuple[Array, Array, Array]: ...


@overload
def signed_distance(px: Array, py: Array, e: Edges, *, normals: Literal[False],
                    outside_beyond: Array | None = None) -> Array: ...


def signed_distance(px: Array, py: Array, e: Edges, *, normals: bool = True, outside_beyond: Array | None = None
                    ) -> tuple[Array, Array, Array] | Array:
    """Signed distance from points to polygons, and the outward unit normal at the nearest point.

    px, py (B...) broadcast against the polygons' batch shape (K,): (P,) with K = P pairs one to one,
    or (N, 1) against (K,) = (M,) for every point against every polygon. Returns d, nx, ny of the
    broadcast shape; d < 0 inside a polygon of >= 3 vertices (CCW); (nx, ny) points from the nearest
    boundary point toward the outside, the direction in which the point must be pushed.
    normals=False: d alone, by the same operations (the minimum d² is the one at its argmin); with
    outside_beyond (broadcast to d), a distance from each polygon's boundary beyond which a point cannot be
    inside it (the radius of a circle that holds the polygon: a disc inside the polygon is inside that
    circle), the inside test is skipped when every point is beyond it.
    """
    apx = px[..., None] - e.ax
    apy = py[..., None] - e.ay
    shape = apx.shape
    same = e.abx.shape == shape
    if not normals:  # the same operations in the broadcast shape, reduced over the last axis
        abx = e.abx if same else np.broadcast_to(e.abx, shape)
        aby = e.aby if same else np.broadcast_to(e.aby, shape)
        t = (apx * abx + apy * aby) * e.inv_den
        np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)  # clip to [0, 1]
        dx = apx - t * abx
        dy = apy - t * aby
        dist = np.sqrt((dx * dx + dy * dy + e.pad).min(axis=-1))
        if outside_beyond is not None and bool((dist > outside_beyond).all()):
            return dist  # every point outside: where(inside, -dist, dist) is dist
        inside = ((abx * apy - aby * apx >= 0.0) | e.invalid).all(axis=-1) & e.closed
        return np.where(inside, -dist, dist)
    v = shape[-1]

    def full(a: NDArray[Any]) -> NDArray[Any]:
        return (a if same else np.broadcast_to(a, shape)).reshape(-1, v)

    apx = apx.reshape(-1, v)
    apy = apy.reshape(-1, v)
    abx = full(e.abx)
    aby = full(e.aby)
    t = (apx * abx + apy * aby) * full(e.inv_den)
    np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)  # clip to [0, 1]
    dx = apx - t * abx  # p - q
    dy = apy - t * aby
    d2 = dx * dx + dy * dy + full(e.pad)
    cross = abx * apy - aby * apx
    inside = ((cross >= 0.0) | full(e.invalid)).all(axis=1)
    inside &= (e.closed if same else np.broadcast_to(e.closed, shape[:-1])).reshape(-1)
    out = shape[:-1]
    k = np.argmin(d2, axis=1)
    rows = np.arange(k.shape[0])
    dist = np.sqrt(d2[rows, k])
    vx = dx[rows, k]
    vy = dy[rows, k]
    # On the boundary (to within 1 nm, where p - q is rounding noise): the edge's outward normal
    # (right-hand side of a CCW edge).
    on_edge = dist <= ON_EDGE_M
    if on_edge.any():
        ex, ey = abx[rows, k], aby[rows, k]
        elen = np.sqrt(ex * ex + ey * ey)
        ok = elen > 0.0
        safe_len = np.where(ok, elen, 1.0)
        vx = np.where(on_edge, np.where(ok, ey / safe_len, 1.0), vx)
        vy = np.where(on_edge, np.where(ok, -ex / safe_len, 0.0), vy)
        dist_safe = np.where(on_edge, 1.0, dist)
        flip = np.where(inside & ~on_edge, -1.0, 1.0)
    else:
        dist_safe = dist
        flip = np.where(inside, -1.0, 1.0)
    # Inside, p - q points inward: flip it so the normal points out of the polygon.
    return (np.where(inside, -dist, dist).reshape(out), (flip * vx / dist_safe).reshape(out),
            (flip * vy / dist_safe).reshape(out))


def distance_to_polygon(points: Array, polygon: Array) -> tuple[Array, Array]:
    """Signed distance of many points to one polygon: (P, 2), (V, 2) -> d (P,), n (P, 2)."""
    d, nx, ny = signed_distance(points[:, 0:1], points[:, 1:2], Edges.of([polygon]))
    return d[:, 0], np.stack([nx[:, 0], ny[:, 0]], axis=1)
