"""reconswarm/geometry/plane.py: canonical hulls, signed distances (against shapely), contour sampling, pairs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import MultiPoint, Point, Polygon

from reconswarm.geometry.plane import (
    Edges,
    convex_hull,
    distance_to_polygon,
    is_strictly_convex,
    merge_hull,
    points_inside_hull,
    polygon_area,
    sample_boundary,
    signed_distance,
)

SETTINGS = settings(max_examples=150, deadline=None)
angle = st.floats(0.0, 2 * math.pi, allow_nan=False, exclude_max=True)

grid_points = st.lists(st.tuples(st.integers(-40, 40), st.integers(-40, 40)), min_size=1, max_size=40).map(
    lambda pts: np.array(pts, dtype=np.float64))
# Inexact (decimal) coordinates, but no near-underflow values: products of 1e-285 coordinates underflow
# and defeat any relative collinearity test.
float_points = st.lists(st.tuples(st.integers(-10**6, 10**6), st.integers(-10**6, 10**6)), min_size=1,
                        max_size=40).map(lambda pts: np.array(pts, dtype=np.float64) / 1000.0)


@st.composite
def convex_polygon(draw, max_size: float = 60.0):
    """A strictly convex CCW polygon: 3-8 points on a rotated ellipse, angles well apart."""
    k = draw(st.integers(3, 8))
    gaps = [draw(st.floats(0.3, 1.0)) for _ in range(k)]
    total = sum(gaps)
    assume(max(gaps) / total * 2 * math.pi < math.pi - 0.1)
    ang = draw(angle) + np.cumsum([0.0, *gaps[:-1]]) / total * 2 * math.pi
    a = draw(st.floats(2.0, max_size))
    b = a * draw(st.floats(0.4, 1.0))
    rot = draw(angle)
    cx, cy = draw(st.floats(-500, 500)), draw(st.floats(-500, 500))
    x, y = a * np.cos(ang), b * np.sin(ang)
    c, s = math.cos(rot), math.sin(rot)
    return np.stack([cx + c * x - s * y, cy + s * x + c * y], axis=1)


def cross(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def assert_canonical_hull_of(hull: np.ndarray, pts: np.ndarray) -> None:
    """The defining properties of the canonical hull of an (exact, integer) point set."""
    uniq = np.unique(pts, axis=0)
    if uniq.shape[0] <= 2:
        np.testing.assert_array_equal(hull, uniq[np.lexsort((uniq[:, 1], uniq[:, 0]))])
        return
    # Starts at the lowest (x, y).
    lowest = uniq[np.lexsort((uniq[:, 1], uniq[:, 0]))][0]
    np.testing.assert_array_equal(hull[0], lowest)
    # Every vertex is an input point.
    assert {tuple(v) for v in hull} <= {tuple(p) for p in uniq}
    v = hull.shape[0]
    if v == 2:  # all input points collinear: the hull is the segment between the extremes
        assert all(cross(hull[0], hull[1], q) == 0 for q in uniq)
        return
    # Strictly convex, counter-clockwise: every turn a strict left turn (collinear points dropped).
    for i in range(v):
        assert cross(hull[i - 1], hull[i], hull[(i + 1) % v]) > 0
    # Every input point inside or on it.
    for q in uniq:
        assert all(cross(hull[i], hull[(i + 1) % v], q) >= 0 for i in range(v))
    # Same area as shapely's hull.
    assert polygon_area(hull) == pytest.approx(MultiPoint([tuple(p) for p in uniq]).convex_hull.area, rel=1e-12)


# ------------------------------------------------------------------------------------------ hulls


@SETTINGS
@given(grid_points)
def test_convex_hull_canonical_properties(pts):
    assert_canonical_hull_of(convex_hull(pts), pts)


@SETTINGS
@given(st.one_of(grid_points, float_points), st.randoms(use_true_random=False))
def test_convex_hull_permutation_and_duplicates_invariant(pts, rnd):
    h = convex_hull(pts)
    perm = list(range(pts.shape[0]))
    rnd.shuffle(perm)
    assert np.array_equal(convex_hull(pts[perm]), h)
    assert np.array_equal(convex_hull(np.concatenate([pts, pts[perm[: len(perm) // 2 + 1]]])), h)


@SETTINGS
@given(grid_points, st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 10**6), st.integers(0, 10**6)),
                             max_size=20))
def test_convex_hull_unchanged_by_interior_and_edge_points(pts, weights):
    h = convex_hull(pts)
    assume(h.shape[0] >= 3)
    extra = []
    v = h.shape[0]
    for k, (a, b, c) in enumerate(weights):
        if k % 2 == 0:
            # An exact point on edge k: the midpoint of a doubled lattice (x2 keeps it exact).
            i = k % v
            extra.append(h[i] + h[(i + 1) % v])
        else:
            # An interior point: a convex combination of three hull vertices, rounded into the interior.
            s = a + b + c + 3
            q = ((a + 1) * h[0] + (b + 1) * h[1] + (c + 1) * h[2]) / s
            extra.append(2 * q)
    scaled = 2 * h
    both = np.concatenate([scaled, np.array(extra).reshape(-1, 2)]) if extra else scaled
    assert np.array_equal(convex_hull(both), scaled)


@SETTINGS
@given(convex_polygon(), st.floats(0.2, 3.0))
def test_hull_of_contour_samples_is_the_polygon(poly, spacing):
    """Samples along straight edges deviate from them by rounding only: the hull drops them all."""
    samples = sample_boundary(poly, spacing)
    h = convex_hull(samples)
    assert np.array_equal(h, convex_hull(poly))
    assert h.shape[0] == poly.shape[0]
    # ... and merging more samples of the same polygon into a partial hull converges to the same array.
    part = convex_hull(samples[::3])
    assert np.array_equal(merge_hull(part, samples), h)


@SETTINGS
@given(st.one_of(grid_points, float_points), st.one_of(grid_points, float_points))
def test_merge_hull_equals_hull_of_union(a, b):
    h = convex_hull(a)
    assert np.array_equal(merge_hull(h, b), convex_hull(np.concatenate([h, b])))
    # For exact (integer) points the canonical hull forgets the interior: hull(h ∪ b) == hull(a ∪ b).
    if np.all(a == np.round(a)) and np.all(b == np.round(b)):
        assert np.array_equal(merge_hull(h, b), convex_hull(np.concatenate([a, b])))
    assert merge_hull(h, np.zeros((0, 2))) is h or np.array_equal(merge_hull(h, np.zeros((0, 2))), h)


def test_convex_hull_small_cases():
    assert convex_hull(np.zeros((0, 2))).shape == (0, 2)
    np.testing.assert_array_equal(convex_hull(np.array([[1.0, 2.0], [1.0, 2.0]])), [[1.0, 2.0]])
    np.testing.assert_array_equal(convex_hull(np.array([[3.0, 0.0], [0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])),
                                  [[0.0, 0.0], [3.0, 0.0]])
    # A square given clockwise with an edge midpoint comes back CCW from its lowest (x, y), 4 vertices.
    sq = np.array([[0.0, 10.0], [10.0, 10.0], [10.0, 5.0], [10.0, 0.0], [0.0, 0.0], [5.0, 5.0]])
    np.testing.assert_array_equal(convex_hull(sq), [[0, 0], [10, 0], [10, 10], [0, 10]])


@SETTINGS
@given(grid_points, grid_points)
def test_points_inside_hull(hull_pts, q):
    h = convex_hull(hull_pts)
    assume(h.shape[0] >= 3)
    shape = Polygon(h)
    got = points_inside_hull(q, h)
    want = [shape.covers(Point(*p)) for p in q]
    assert got.tolist() == want


# ------------------------------------------------------------------------------------------ convexity


def test_is_strictly_convex():
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert is_strictly_convex(sq) and is_strictly_convex(sq[::-1])
    assert not is_strictly_convex(np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]))  # collinear
    assert not is_strictly_convex(np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.5], [2.0, 2.0], [0.0, 2.0]]))  # dent
    pentagram = np.array([[math.cos(a), math.sin(a)] for a in np.arange(5) * 4 * math.pi / 5])
    assert not is_strictly_convex(pentagram)  # turns one way everywhere but winds twice
    assert not is_strictly_convex(sq[:2])


@SETTINGS
@given(convex_polygon())
def test_random_convex_polygons_are_strictly_convex(poly):
    assert is_strictly_convex(poly) and is_strictly_convex(poly[::-1])
    assert polygon_area(poly) > 0 > polygon_area(poly[::-1])
    size = float(np.max(np.abs(poly)))
    assert polygon_area(poly) == pytest.approx(Polygon(poly).area, rel=1e-9, abs=1e-13 * size * size)


# ------------------------------------------------------------------------------------------ distances


@SETTINGS
@given(convex_polygon(), st.lists(st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)), min_size=1, max_size=30))
def test_signed_distance_matches_shapely(poly, rel):
    shape = Polygon(poly)
    c = poly.mean(axis=0)
    size = float(np.max(np.hypot(*(poly - c).T)))
    pts = c + size * np.array(rel)
    d, n = distance_to_polygon(pts, poly)
    for k, q in enumerate(pts):
        pt = Point(*q)
        boundary = shape.exterior.distance(pt)
        if shape.contains(pt):
            assert d[k] < 0
        elif boundary > 1e-9 * size:
            assert d[k] > 0
        assert abs(d[k]) == pytest.approx(boundary, rel=1e-9, abs=1e-9 * size)
        assert math.hypot(*n[k]) == pytest.approx(1.0, rel=1e-12)
        # The nearest boundary point is q - d n, and it lies on the boundary.
        near = q - d[k] * n[k]
        assert shape.exterior.distance(Point(*near)) <= 1e-9 * size
    # Row independence: each point alone gives bit-identical results.
    for k in range(pts.shape[0]):
        dk, nk = distance_to_polygon(pts[k:k + 1], poly)
        assert dk[0] == d[k] and np.array_equal(nk[0], n[k])


@SETTINGS
@given(convex_polygon(), st.lists(st.tuples(st.floats(-4.0, 4.0), st.floats(-4.0, 4.0)), min_size=1, max_size=30))
def test_signed_distance_outside_beyond_changes_nothing(poly, rel):
    """The inside test skipped for points all farther from the boundary than the polygon's bounding circle
    (sensing's true distances): the same distances bit for bit, inside points included (never skipped)."""
    c = poly.mean(axis=0)
    reach = float(np.max(np.hypot(*(poly - c).T)))
    pts = c + reach * np.array(rel)
    e = Edges.of([poly])
    plain = signed_distance(pts[:, 0:1], pts[:, 1:2], e, normals=False)
    beyond = np.array([reach * (1 + 1e-9) + 1e-9])
    assert signed_distance(pts[:, 0:1], pts[:, 1:2], e, normals=False, outside_beyond=beyond).tobytes() \
        == plain.tobytes()
    for k in range(pts.shape[0]):  # each point alone: the shortcut is taken whenever it is outside the circle
        one = signed_distance(pts[k:k + 1, 0:1], pts[k:k + 1, 1:2], e, normals=False, outside_beyond=beyond)
        assert one.tobytes() == plain[k:k + 1].tobytes()


@SETTINGS
@given(convex_polygon(), st.integers(0, 7), st.floats(0.0, 1.0))
def test_signed_distance_zero_on_boundary_with_outward_normal(poly, edge, t):
    v = poly.shape[0]
    a, b = poly[edge % v], poly[(edge + 1) % v]
    q = a + t * (b - a)
    d, _ = distance_to_polygon(q[None], poly)
    size = float(np.max(np.abs(poly)))
    assert abs(d[0]) <= 1e-12 * size
    # Slightly off the boundary (beyond rounding), the normal is the edge's outward normal (CCW: right side).
    e = b - a
    out_n = np.array([e[1], -e[0]]) / math.hypot(*e)
    eps = 1e-7 * size
    dd, nn = distance_to_polygon(np.stack([q + eps * out_n, q - eps * out_n]), poly)
    assert dd[0] == pytest.approx(eps, rel=1e-5)  # outside along the outward normal
    if 0.01 < t < 0.99:  # away from the corners, the nearest point is on this edge, from both sides
        assert dd[1] == pytest.approx(-eps, rel=1e-5)
        np.testing.assert_allclose(nn, [out_n, out_n], atol=1e-6)
    # Exactly on an axis-aligned edge (no rounding at all): d is 0 and the normal is the edge's.
    sq = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0]])
    d0, n0 = distance_to_polygon(np.array([[8.0 * t, 0.0], [8.0, 8.0 * t]]), sq)
    assert np.array_equal(np.abs(d0), [0.0, 0.0])
    if 0.01 < t < 0.99:
        np.testing.assert_allclose(n0, [[0.0, -1.0], [1.0, 0.0]], atol=1e-15)


def test_signed_distance_normal_within_rounding_of_an_edge():
    poly = np.array([[1.9214184860311239, 0.22204540131706907], [-1.5317613773090513, 0.5143861713513346],
                     [-0.47996684718033167, -0.77662158874013]])
    q = np.array([[-0.23681892855648545, 0.404758382588485]])  # on edge 0 up to rounding
    d, n = distance_to_polygon(q, poly)
    assert abs(d[0]) < 1e-15
    e = poly[1] - poly[0]
    out_n = np.array([e[1], -e[0]]) / math.hypot(*e)
    assert float(n[0] @ out_n) > 0.99


def test_signed_distance_on_vertex_and_inside_square():
    sq = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    d, n = distance_to_polygon(np.array([[10.0, 10.0], [5.0, 5.0], [2.0, 5.0], [12.0, 5.0], [13.0, 14.0]]), sq)
    assert d[0] == 0.0 and math.hypot(*n[0]) == pytest.approx(1.0)
    np.testing.assert_allclose(d[1:], [-5.0, -2.0, 2.0, 5.0])
    np.testing.assert_allclose(n[2], [-1.0, 0.0])  # inside: the way out through the nearest face
    np.testing.assert_allclose(n[3], [1.0, 0.0])
    np.testing.assert_allclose(n[4], [0.6, 0.8])


@settings(max_examples=60, deadline=None)
@given(st.lists(convex_polygon(), min_size=1, max_size=4), st.integers(0, 2**32 - 1))
def test_batched_padded_edges_are_bit_identical_to_single_polygon_calls(polys, seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-600, 600, (7, 2))
    e = Edges.of(polys)
    d, nx, ny = signed_distance(pts[:, 0:1], pts[:, 1:2], e)  # (7, M) every point against every polygon
    assert d.shape == (7, len(polys))
    for m, poly in enumerate(polys):
        dm, nm = distance_to_polygon(pts, poly)
        assert np.array_equal(d[:, m], dm)
        assert np.array_equal(np.stack([nx[:, m], ny[:, m]], axis=1), nm)
    # One to one: point q against polygon q.
    k = len(polys)
    d1, _, _ = signed_distance(pts[:k, 0], pts[:k, 1], e)
    assert np.array_equal(d1, d[np.arange(k), np.arange(k)])


def test_degenerate_hulls_point_and_segment():
    e = Edges.of([np.array([[1.0, 1.0]]), np.array([[0.0, 0.0], [4.0, 0.0]])])
    d, nx, ny = signed_distance(np.array([[4.0], [2.0]]), np.array([[5.0], [-3.0]]), e)
    np.testing.assert_allclose(d, [[5.0, 5.0], [math.hypot(1, 4), 3.0]])
    np.testing.assert_allclose([nx[1, 1], ny[1, 1]], [0.0, -1.0])  # never "inside" a segment


# ------------------------------------------------------------------------------------------ sampling


@SETTINGS
@given(convex_polygon(max_size=80.0), st.floats(0.1, 5.0))
def test_sample_boundary_spacing_vertices_and_on_boundary(poly, spacing):
    s = sample_boundary(poly, spacing)
    # Consecutive samples along the closed contour are at most `spacing` apart.
    gaps = np.hypot(*(np.roll(s, -1, axis=0) - s).T)
    assert gaps.max() <= spacing * (1 + 1e-12)
    # Every vertex is a sample, in order.
    idx = [int(np.flatnonzero(np.all(s == v, axis=1))[0]) for v in poly]
    assert idx == sorted(idx) and idx[0] == 0
    # Every sample lies on the boundary.
    ext = Polygon(poly).exterior
    size = float(np.max(np.abs(poly)))
    assert max(ext.distance(Point(*q)) for q in s) <= 1e-12 * size
    # As few as the spacing allows: ceil(edge / spacing) per edge.
    edges = np.hypot(*(np.roll(poly, -1, axis=0) - poly).T)
    assert s.shape[0] == sum(max(1, math.ceil(float(x) / spacing)) for x in edges)
