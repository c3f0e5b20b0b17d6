"""The control law of reconswarm/paper/planner.py against the paper's potentials (eqs. 8-11), written out here.

The oracles below are the paper's *potentials* U_att (eq. 8, R_i* = R_c) and U_rep (eq. 10), not its
gradients: the planner's output must equal -∇U by central finite differences (sign convention of
docs/paper.md: u = -(∇U_att + ∇U_rep^a + ∇U_rep^o), Ψ < 0).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import Point, Polygon

from reconswarm.geometry.pairs import pairs_within
from reconswarm.paper.planner import (
    Neighbours,
    ObstacleView,
    _accumulate,
    agent_repulsion,
    attraction,
    command,
    containment,
    errors,
    max_repulsion_speed,
    neighbour_table,
    obstacle_repulsion,
    repulsion_speed,
)
from reconswarm.scenario.model import PlannerConfig, PlannerKind
from tests.support import view_of

SETTINGS = settings(max_examples=120, deadline=None)
H = 1e-4  # finite-difference step (m)


# ------------------------------------------------------------------------------------------ oracles


def u_att(p: np.ndarray, c: np.ndarray, delta: np.ndarray, k: float, rc: float) -> float:
    """Eq. (8) with R_i* = R_c."""
    r = math.hypot(*(p - c))
    if r <= rc:
        e = p - (c + delta)
        return 0.5 * k * float(e @ e) * (rc / rc)
    return rc * k * r - 0.5 * k * rc * rc


def u_rep_term(d: float, d_min: float, d_max: float, psi: float, d_contact: float) -> float:
    """One summand of eq. (10), expanded exactly as printed in the paper, for d >= d_contact (surface gap
    >= 0); inside contact it continues along its tangent (the bounded repulsion: constant force)."""
    if d > d_max:
        return 0.0
    den = d_min - d_max
    if d < d_contact:
        slope = psi / den * d_contact - psi * d_max / den
        return u_rep_term(d_contact, d_min, d_max, psi, d_contact) + slope * (d - d_contact)
    return psi / (2 * den) * d * d - psi * d_max / den * d + psi * d_max * d_max / (2 * den)


def grad_fd(f, p: np.ndarray, h: float = H) -> np.ndarray:
    """Central finite-difference gradient of a scalar function of a 2-vector."""
    g = np.zeros(2)
    for a in range(2):
        e = np.zeros(2)
        e[a] = h
        g[a] = (f(p + e) - f(p - e)) / (2 * h)
    return g


def poly_distance(poly: Polygon, q: np.ndarray) -> float:
    """Unsigned distance from a point outside to a polygon (shapely, independent of our geometry)."""
    return float(poly.distance(Point(float(q[0]), float(q[1]))))


# ------------------------------------------------------------------------------------------ strategies

coord = st.floats(-500.0, 500.0, allow_nan=False)
angle = st.floats(0.0, 2 * math.pi, allow_nan=False, exclude_max=True)


@st.composite
def attraction_case(draw):
    c = np.array([draw(coord), draw(coord)])
    rc = draw(st.floats(5.0, 200.0))
    k = draw(st.floats(0.01, 1.0))
    # The slot offset lies inside the disk (the paper's formation sits in B(p*, R_c)).
    da, dr = draw(angle), draw(st.floats(0.0, 0.95))
    delta = rc * dr * np.array([math.cos(da), math.sin(da)])
    # Stay 1 % of R_c away from the switch ‖p - p*‖ = R_c (the finite difference must not straddle it).
    ratio = draw(st.one_of(st.floats(0.0, 0.99), st.floats(1.01, 8.0)))
    a = draw(angle)
    p = c + rc * ratio * np.array([math.cos(a), math.sin(a)])
    return p, c, delta, k, rc


@st.composite
def repulsion_case(draw):
    """Agent i and up to 6 neighbours, each either inside its field or beyond it, away from both breakpoints of
    eq. (10)'s term (d_max, and contact where it goes on along its tangent) by more than the finite-difference
    step: a central difference across one is not the gradient there (seen: a neighbour exactly at contact)."""
    d_safe = draw(st.floats(0.0, 5.0))
    d_max = d_safe + draw(st.floats(1.0, 20.0))
    psi = -draw(st.floats(1.0, 100.0))
    ri = draw(st.floats(0.5, 5.0))
    p = np.array([draw(coord), draw(coord)])
    k = draw(st.integers(1, 6))
    nb_p, nb_r = [], []
    for _ in range(k):
        rj = draw(st.floats(0.5, 5.0))
        dmx = ri + rj + d_max
        frac = draw(st.one_of(st.floats(0.05, 0.97), st.floats(1.03, 2.0)))
        assume(abs(frac * dmx - (ri + rj)) > 10 * H)
        a = draw(angle)
        nb_p.append(p + frac * dmx * np.array([math.cos(a), math.sin(a)]))
        nb_r.append(rj)
    return p, ri, np.array(nb_p), np.array(nb_r), d_safe, d_max, psi


@st.composite
def convex_polygon(draw, centre=None, size=None):
    """A strictly convex CCW polygon: 3-8 points on a rotated ellipse, angles well apart."""
    k = draw(st.integers(3, 8))
    gaps = [draw(st.floats(0.3, 1.0)) for _ in range(k)]
    total = sum(gaps)
    assume(max(gaps) / total * 2 * math.pi < math.pi - 0.1)
    start = draw(angle)
    ang = start + np.cumsum([0.0, *gaps[:-1]]) / total * 2 * math.pi
    a = size if size is not None else draw(st.floats(3.0, 60.0))
    b = a * draw(st.floats(0.4, 1.0))
    rot = draw(angle)
    cx, cy = centre if centre is not None else (draw(coord), draw(coord))
    x, y = a * np.cos(ang), b * np.sin(ang)
    c, s = math.cos(rot), math.sin(rot)
    return np.stack([cx + c * x - s * y, cy + s * x + c * y], axis=1)


# ------------------------------------------------------------------------------------------ attraction


@SETTINGS
@given(attraction_case())
def test_attraction_is_minus_gradient_of_eq8(case):
    p, c, delta, k, rc = case
    got = attraction(p[None], c, delta[None], k, rc)[0]
    want = -grad_fd(lambda q: u_att(q, c, delta, k, rc), p)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)


@SETTINGS
@given(attraction_case())
def test_attraction_bounds_and_direction(case):
    p, c, delta, k, rc = case
    u = attraction(p[None], c, delta[None], k, rc)[0]
    rel = p - c
    if math.hypot(*rel) > rc:
        # Outside the target disk: constant magnitude R_c k_att, straight toward p*.
        assert math.hypot(*u) == pytest.approx(rc * k, rel=1e-12)
        assert abs(u[0] * rel[1] - u[1] * rel[0]) <= 1e-9 * rc * k * math.hypot(*rel)
        assert u @ rel < 0
    else:
        # Inside: -k_att e_i, i.e. toward the slot, proportional to the error, never above R_c k_att * 2.
        e = p - (c + delta)
        np.testing.assert_allclose(u, -k * e, rtol=1e-12, atol=1e-12)
        assert math.hypot(*u) <= 2 * rc * k


def test_attraction_switch_and_batch_rows():
    c = np.array([800.0, 0.0])
    k, rc = 0.08, 80.0
    delta = np.array([[0.0, 41.57], [12.0, -20.78]])
    # On the circle (‖p - p*‖ = R_c exactly): the inside branch -k e applies.
    p_on = np.array([[880.0, 0.0], [800.0, -80.0]])
    np.testing.assert_allclose(attraction(p_on, c, delta, k, rc), -k * (p_on - c - delta), rtol=0, atol=1e-15)
    # Just outside: the bounded branch; the jump between the two is k_att Δ_i (documented in the planner).
    p_out = np.array([[880.0 + 1e-9, 0.0], [800.0, -80.0 - 1e-9]])
    out = attraction(p_out, c, delta, k, rc)
    np.testing.assert_allclose(out - attraction(p_on, c, delta, k, rc), -k * delta, atol=1e-8)
    # Rows are independent: one agent computed alone is bit-identical to its row in the batch.
    rng = np.random.default_rng(1)
    p = c + rng.uniform(-300, 300, (50, 2))
    off = rng.uniform(-40, 40, (50, 2))
    full = attraction(p, c, off, k, rc)
    for i in range(50):
        assert np.array_equal(attraction(p[i:i + 1], c, off[i:i + 1], k, rc)[0], full[i])
    # At p* itself the attraction is finite (no 0/0).
    assert np.all(np.isfinite(attraction(c[None], c, np.zeros((1, 2)), k, rc)))


# ------------------------------------------------------------------------------------------ repulsion


@SETTINGS
@given(st.floats(0.0, 10.0), st.floats(0.5, 30.0), st.floats(1.0, 100.0), st.floats(0.0, 1.0))
def test_repulsion_speed_profile(d_min, width, mag, frac):
    d_max = d_min + width
    psi = -mag
    contact = d_min - width  # d_safe = width here: contact lies one width below d_min
    at = lambda d: float(repulsion_speed(np.array(d), np.array(d_min), np.array(d_max), psi,  # noqa: E731
                                         np.array(contact)))
    assert at(d_min) == pytest.approx(mag, rel=1e-15)  # |Ψ| at d_min
    assert at(d_max) == 0.0  # zero at d_max
    assert at(d_max + width * frac + 1e-9) == 0.0  # and beyond
    assert at(d_min + frac * width) == pytest.approx(mag * (1 - frac), rel=1e-9, abs=1e-9)  # linear
    assert at(d_min - frac * width) == pytest.approx(mag * (1 + frac), rel=1e-9)  # continues upward to contact
    # ... and stays at its contact value inside it: bounded, |Ψ| d_max / (d_max - d_safe) (= 2 |Ψ| here).
    cap = max_repulsion_speed(psi, width, 2 * width)
    assert cap == pytest.approx(2 * mag, rel=1e-12)
    for inside in (contact, contact - frac * width, contact - 1e6, -1e300):
        assert at(inside) == pytest.approx(cap, rel=1e-9)


@SETTINGS
@given(repulsion_case())
def test_agent_repulsion_is_minus_gradient_of_eq10(case):
    p, ri, nb_p, nb_r, d_safe, d_max, psi = case

    def u_rep(q: np.ndarray) -> float:
        total = 0.0
        for pj, rj in zip(nb_p, nb_r, strict=True):
            total += u_rep_term(math.hypot(*(q - pj)), ri + rj + d_safe, ri + rj + d_max, psi, ri + rj)
        return total

    valid = np.ones((1, len(nb_r)), dtype=bool)
    got = agent_repulsion(p[None], np.array([ri]), nb_p[None], nb_r[None], valid, d_safe, d_max, psi)[0]
    want = -grad_fd(u_rep, p)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
    # Bounded (no 1/d blow-up, and no growth inside contact): each term at most |Ψ| d_max / (d_max - d_safe).
    bound = len(nb_r) * abs(psi) * d_max / (d_max - d_safe)
    assert math.hypot(*got) <= bound * (1 + 1e-12)


@SETTINGS
@given(st.floats(0.5, 6.0), st.floats(0.5, 6.0), st.floats(0.0, 5.0), st.floats(1.0, 20.0),
       st.floats(1.0, 100.0), angle, st.floats(0.0, 1.0))
def test_agent_repulsion_bounds(ri, rj, d_safe, width, mag, a, frac):
    d_max = d_safe + width
    psi = -mag
    d_min_ij = ri + rj + d_safe
    d_max_ij = ri + rj + d_max
    unit = np.array([math.cos(a), math.sin(a)])

    def rep(d: float) -> np.ndarray:
        pj = np.array([[[10.0, -20.0]]])
        pi = np.array([[10.0, -20.0]]) + d * unit
        return agent_repulsion(pi, np.array([ri]), pj, np.array([[rj]]), np.ones((1, 1), bool), d_safe, d_max, psi)[0]

    u = rep(d_min_ij)
    assert math.hypot(*u) == pytest.approx(mag, rel=1e-9)  # |Ψ| at d_min,ij
    assert u @ unit == pytest.approx(mag, rel=1e-9)  # pushing i away from j
    assert np.array_equal(rep(d_max_ij * (1 + 1e-12) + 1e-12), np.zeros(2))  # nothing beyond d_max,ij
    assert math.hypot(*rep(d_max_ij * 1.5)) == 0.0
    d = d_min_ij + frac * (d_max_ij - d_min_ij)
    assert math.hypot(*rep(d)) == pytest.approx(mag * (1 - frac), rel=1e-7, abs=1e-7)  # linear between
    # Invalid table entries contribute nothing.
    pj = np.array([[[10.0, -20.0]]])
    pi = np.array([[10.0, -20.0]]) + d_min_ij * unit
    off = agent_repulsion(pi, np.array([ri]), pj, np.array([[rj]]), np.zeros((1, 1), bool), d_safe, d_max, psi)
    assert np.array_equal(off, np.zeros((1, 2)))


def test_agent_repulsion_exact_d_min_on_axis():
    # d computed exactly (axis-aligned): the magnitude is exactly |Ψ|, at d_max exactly 0.
    ri, rj, d_safe, d_max, psi = 2.6, 4.58, 2.0, 10.0, -65.0
    for d, want in ((ri + rj + d_safe, 65.0), (ri + rj + d_max, 0.0)):
        u = agent_repulsion(np.array([[d, 0.0]]), np.array([ri]), np.zeros((1, 1, 2)), np.array([[rj]]),
                            np.ones((1, 1), bool), d_safe, d_max, psi)[0]
        assert u[0] == pytest.approx(want, abs=1e-12)
        assert u[1] == 0.0
    # Coincident centres: finite (a fixed direction), never NaN.
    u = agent_repulsion(np.zeros((1, 2)), np.array([1.0]), np.zeros((1, 1, 2)), np.array([[1.0]]),
                        np.ones((1, 1), bool), d_safe, d_max, psi)
    assert np.all(np.isfinite(u)) and math.hypot(*u[0]) > 65.0


@SETTINGS
@given(st.integers(2, 25), st.integers(0, 2**32 - 1), st.floats(5.0, 60.0))
def test_agent_repulsion_antisymmetric_and_sums_to_zero(n, seed, spread):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-spread, spread, (n, 2))
    r = rng.uniform(0.5, 4.0, n)
    d_safe, d_max, psi = 2.0, 10.0, -65.0
    # Pairwise: the term on i from j is exactly minus the term on j from i.
    one = np.ones((1, 1), bool)
    for i in range(n):
        for j in range(i + 1, n):
            on_i = agent_repulsion(p[i:i + 1], r[i:i + 1], p[None, j:j + 1], r[None, j:j + 1], one, d_safe, d_max, psi)
            on_j = agent_repulsion(p[j:j + 1], r[j:j + 1], p[None, i:i + 1], r[None, i:i + 1], one, d_safe, d_max, psi)
            assert np.array_equal(on_i, -on_j)
    # Over the whole swarm (tables from neighbour_table), the repulsions sum to zero.
    nb = neighbour_table(p, r, pairs_within(p, 2 * float(r.max()) + d_max), d_max)
    u = agent_repulsion(p, r, nb.p, nb.r, nb.valid, d_safe, d_max, psi)
    scale = max(1.0, float(np.abs(u).sum()))
    assert np.abs(u.sum(axis=0)).max() <= 1e-12 * scale


@SETTINGS
@given(st.integers(1, 40), st.integers(0, 2**32 - 1))
def test_neighbour_table_matches_brute_force_and_rows_are_bit_identical(n, seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-40, 40, (n, 2))
    r = rng.uniform(0.5, 4.0, n)
    d_safe, d_max, psi = 2.0, 10.0, -65.0
    # Candidate pairs: a superset (every pair); the table must keep exactly those within d_max,ij.
    cand = np.array([(i, j) for i in range(n) for j in range(i + 1, n)], dtype=np.int64).reshape(-1, 2)
    nb = neighbour_table(p, r, cand, d_max)
    full = agent_repulsion(p, r, nb.p, nb.r, nb.valid, d_safe, d_max, psi)
    for i in range(n):
        # Agent i's own table, built independently: neighbours within d_max,ij in increasing index.
        js = [j for j in range(n) if j != i and math.sqrt((p[i, 0] - p[j, 0]) ** 2 + (p[i, 1] - p[j, 1]) ** 2)
              <= r[i] + r[j] + d_max]
        row = nb.valid[i]
        assert list(np.flatnonzero(row)) == list(range(len(js)))  # valid entries packed to the left
        np.testing.assert_array_equal(nb.p[i, : len(js)], p[js].reshape(-1, 2))
        np.testing.assert_array_equal(nb.r[i, : len(js)], r[js])
        own = agent_repulsion(p[i:i + 1], r[i:i + 1], p[js].reshape(1, -1, 2), r[js].reshape(1, -1),
                              np.ones((1, len(js)), bool), d_safe, d_max, psi)
        # The distributed agent computing its own row gets the same bits as the whole-swarm engine.
        assert np.array_equal(own[0], full[i])


# ------------------------------------------------------------------------------------------ obstacles


@SETTINGS
@given(convex_polygon(centre=(100.0, -50.0)), st.floats(0.5, 5.0), st.floats(0.0, 4.0), st.floats(1.0, 15.0),
       st.floats(1.0, 100.0), st.integers(0, 7), st.floats(0.01, 0.99), st.booleans(), st.floats(0.02, 0.97))
def test_obstacle_repulsion_is_minus_gradient_with_surface_distance(poly, ri, d_safe, width, mag, edge, t,
                                                                      at_vertex, frac):
    d_max = d_safe + width
    psi = -mag
    shape = Polygon(poly)
    # A point at surface distance d (outside, inside the field, away from d_max) whose nearest point of the
    # polygon is known by construction: on an edge (along its normal) or a vertex (inside its normal cone).
    d = frac * (ri + d_max)
    assume(d > 0.05)
    v = poly.shape[0]
    i = edge % v
    a, b = poly[i], poly[(i + 1) % v]
    normal = lambda u: np.array([u[1], -u[0]]) / math.hypot(*u)  # noqa: E731  (outward for CCW)
    if at_vertex:
        n_prev, n_next = normal(a - poly[i - 1]), normal(b - a)
        n = (1 - t) * n_prev + t * n_next
        n /= math.hypot(*n)
        q = a
    else:
        n = normal(b - a)
        q = a + t * (b - a)
    p = q + d * n
    d_true = poly_distance(shape, p)
    assert d_true == pytest.approx(d, rel=1e-9, abs=1e-9)  # the construction is right (shapely agrees)

    def u_rep(x: np.ndarray) -> float:
        return u_rep_term(poly_distance(shape, x), ri + d_safe, ri + d_max, psi, ri)

    view = view_of(p[None], 1, 1, [(0, 0, poly)])
    got = obstacle_repulsion(np.array([ri]), view.d, view.n, view.valid, d_safe, d_max, psi)[0]
    # (h small: where the face and vertex regions meet, the distance's curvature jumps, so the central
    # difference is only O(h / d) accurate there; t stays off those seams (t = 0 or 1 is exactly on one,
    # where hypothesis found a 2.6e-5 difference). The exact checks below hold everywhere.)
    want = -grad_fd(u_rep, p, h=1e-7)
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=2e-5)
    # Magnitude from the surface distance; direction from the nearest point of the polygon to p.
    expect_mag = mag * ((ri + d_max) - max(d, ri)) / (d_max - d_safe)  # constant once in contact (d < r_i)
    assert math.hypot(*got) == pytest.approx(expect_mag, rel=1e-9, abs=1e-9)
    np.testing.assert_allclose(got, expect_mag * n, atol=1e-8)


def test_obstacle_repulsion_bounds_against_a_face():
    # Square [0, 10]²; an agent to its right at surface distance d along +x (nearest point on the face).
    sq = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    ri, d_safe, d_max, psi = 3.0, 2.0, 10.0, -65.0

    def rep(d: float) -> np.ndarray:
        view = view_of(np.array([[10.0 + d, 4.0]]), 1, 1, [(0, 0, sq)])
        return obstacle_repulsion(np.array([ri]), view.d, view.n, view.valid, d_safe, d_max, psi)[0]

    np.testing.assert_allclose(rep(ri + d_safe), [65.0, 0.0], atol=1e-12)  # |Ψ| at d_min = r + d_safe
    np.testing.assert_allclose(rep(ri + d_max), [0.0, 0.0], atol=0)  # 0 at d_max = r + d_max
    assert np.array_equal(rep(ri + d_max + 0.5), np.zeros(2))
    np.testing.assert_allclose(rep(ri + d_safe + 2.0), [65.0 * 6 / 8, 0.0], atol=1e-12)  # linear
    # Between d_min and contact (surface gap 0, d = r_i) the line continues upward ...
    np.testing.assert_allclose(rep(ri + 0.5), [65.0 * 9.5 / 8, 0.0], atol=1e-12)
    # ... and stops there: in contact, or inside the obstacle (d < 0), the push keeps its contact value
    # |Ψ| d_max / (d_max - d_safe) and still points out through the near face.
    for d in (ri, ri - 1.0, -1.0):
        view = view_of(np.array([[10.0 + d, 4.0]]), 1, 1, [(0, 0, sq)])
        assert view.d[0, 0] == pytest.approx(d)
        u = obstacle_repulsion(np.array([ri]), view.d, view.n, view.valid, d_safe, d_max, psi)[0]
        np.testing.assert_allclose(u, [65.0 * 10 / 8, 0.0], atol=1e-12)
    # Near a corner the push points from the corner to the agent.
    p = np.array([[10.0 + 3.0, 10.0 + 4.0]])  # 5 m from (10, 10)
    view = view_of(p, 1, 1, [(0, 0, sq)])
    u = obstacle_repulsion(np.array([ri]), view.d, view.n, view.valid, d_safe, d_max, psi)[0]
    np.testing.assert_allclose(u, 65.0 * 8 / 8 * np.array([0.6, 0.8]), atol=1e-12)


def test_obstacle_view_columns_and_validity():
    sq = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    tri = np.array([[20.0, 0.0], [30.0, 0.0], [25.0, 8.0]])
    p = np.array([[15.0, 5.0], [-5.0, 5.0]])
    view = view_of(p, 2, 2, [(0, 0, sq), (0, 1, tri), (1, 0, sq)])
    assert view.valid.tolist() == [[True, True], [True, False]]
    assert view.d[0, 0] == pytest.approx(5.0) and view.d[1, 0] == pytest.approx(5.0)
    assert view.d[0, 1] == pytest.approx(Polygon(tri).distance(Point(15.0, 5.0)))
    np.testing.assert_allclose(view.n[1, 0], [-1.0, 0.0])
    # A knowledge of one sample point (a 1-vertex hull) or a segment still gives a distance and a direction.
    seg = np.array([[10.0, -1.0], [10.0, 9.0]])
    v1 = view_of(np.array([[3.0, 4.0]]), 1, 2, [(0, 0, np.zeros((1, 2))), (0, 1, seg)])
    np.testing.assert_allclose(v1.d[0], [5.0, 7.0])
    np.testing.assert_allclose(v1.n[0, 0], [0.6, 0.8])
    np.testing.assert_allclose(v1.n[0, 1], [-1.0, 0.0])


# ------------------------------------------------------------------------------------------ containment


@SETTINGS
@given(st.floats(40.0, 120.0), st.floats(0.5, 5.0), angle, st.floats(0.03, 0.97))
def test_containment_is_minus_gradient_of_wall_potential(rc, ri, a, frac):
    d_safe, d_max, psi = 2.0, 10.0, -65.0
    c = np.array([5.0, -7.0])
    # Distance to the disk's edge from inside: d = R_c - ‖p - c‖, in (0, r + d_max) away from the ends.
    d = frac * (ri + d_max)
    assume(abs(d - ri) > 10 * H)  # (contact: the potential turns linear there; a difference across it is off by O(H))
    p = c + (rc - d) * np.array([math.cos(a), math.sin(a)])

    def u_wall(q: np.ndarray) -> float:
        return u_rep_term(rc - math.hypot(*(q - c)), ri + d_safe, ri + d_max, psi, ri)

    got = containment(p[None], np.array([ri]), c[None], rc, d_safe, d_max, psi)[0]
    np.testing.assert_allclose(got, -grad_fd(u_wall, p), rtol=1e-6, atol=1e-6)
    assert got @ (c - p) >= 0  # pushes inward
    # Deep inside and outside the disk: no containment force.
    deep = c + (rc - ri - d_max - 1.0) * np.array([math.cos(a), math.sin(a)])
    out = c + (rc + 1.0) * np.array([math.cos(a), math.sin(a)])
    z = containment(np.stack([deep, out]), np.array([ri, ri]), np.stack([c, c]), rc, d_safe, d_max, psi)
    assert np.array_equal(z, np.zeros((2, 2)))


# ------------------------------------------------------------------------------------------ eq. (7)


CFG = PlannerConfig(kind=PlannerKind.RECONFIGURABLE, k_att=0.08, target_radius_m=80.0, psi_mps=-65.0, d_safe_m=2.0,
                    d_max_m=10.0, sensing_range_m=40.0, link_range_m=40.0)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0))
def test_command_is_minus_gradient_of_total_potential(seed, px, py):
    """u_i = -(∇U_att + ∇U_rep^a + ∇U_rep^o) + perturbation, checked on one agent with everything active."""
    rng = np.random.default_rng(seed)
    c = np.array([800.0, 0.0])
    delta = np.array([12.0, -20.78])
    ri = 3.0
    poly = np.array([[300.0, -45.0], [345.0, 0.0], [300.0, 45.0], [255.0, 0.0]])
    shape = Polygon(poly)
    p = np.array([345.0 + 8.0, 0.0]) + rng.uniform(-2.0, 2.0, 2)  # outside the disk, near the diamond's tip
    p = p + np.array([px, py]) * 0.1
    nb_p = p + rng.uniform(-12.0, 12.0, (3, 2))
    nb_r = rng.uniform(1.0, 4.0, 3)
    dists = np.hypot(*(nb_p - p).T)
    assume(np.all(np.abs(dists - (ri + nb_r + CFG.d_max_m)) > 1e-2) and np.all(dists > 0.5))
    d_obs = poly_distance(shape, p)
    assume(d_obs > 0.1 and abs(d_obs - (ri + CFG.d_max_m)) > 1e-2)

    def total(q: np.ndarray) -> float:
        u = u_att(q, c, delta, CFG.k_att, CFG.target_radius_m)
        for pj, rj in zip(nb_p, nb_r, strict=True):
            u += u_rep_term(math.hypot(*(q - pj)), ri + rj + CFG.d_safe_m, ri + rj + CFG.d_max_m, CFG.psi_mps,
                              ri + rj)
        u += u_rep_term(poly_distance(shape, q), ri + CFG.d_safe_m, ri + CFG.d_max_m, CFG.psi_mps, ri)
        return u

    nb = Neighbours(nb_p[None], nb_r[None], np.ones((1, 3), bool))
    ob = view_of(p[None], 1, 1, [(0, 0, poly)])
    pert = np.array([[0.3, -0.2]])
    got = command(CFG, p[None], np.array([ri]), delta[None], c[None], nb, ob, pert)[0]
    want = -grad_fd(total, p, h=1e-5) + pert[0]
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


def test_command_virtual_leader_adds_feedforward_and_containment():
    rng = np.random.default_rng(3)
    n = 6
    v = np.array([[100.0, 5.0]])
    center = np.broadcast_to(v, (n, 2))
    p = v + rng.uniform(-75.0, 75.0, (n, 2))
    r = rng.uniform(2.0, 4.0, n)
    off = rng.uniform(-30.0, 30.0, (n, 2))
    nb = neighbour_table(p, r, pairs_within(p, 40.0), CFG.d_max_m)
    ob = ObstacleView.empty(n)
    vel = np.broadcast_to(np.array([[6.4, 0.0]]), (n, 2))
    pert = np.zeros((n, 2))
    cfg = PlannerConfig(**{**CFG.__dict__, "kind": PlannerKind.VIRTUAL_LEADER})
    got = command(cfg, p, r, off, center, nb, ob, pert, vel)
    want = (attraction(p, center, off, cfg.k_att, cfg.target_radius_m)
            + agent_repulsion(p, r, nb.p, nb.r, nb.valid, cfg.d_safe_m, cfg.d_max_m, cfg.psi_mps)
            + vel
            + containment(p, r, center, cfg.target_radius_m, cfg.d_safe_m, cfg.d_max_m, cfg.psi_mps))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # Without a leader velocity (reconfigurable) there is no containment term.
    plain = command(CFG, p, r, off, center, nb, ob, pert)
    np.testing.assert_allclose(plain, want - vel - containment(p, r, center, 80.0, 2.0, 10.0, -65.0), atol=1e-12)


def test_errors_are_slot_distances():
    p = np.array([[803.0, 4.0], [800.0, 0.0]])
    off = np.array([[0.0, 0.0], [0.0, 41.57]])
    np.testing.assert_allclose(errors(p, np.array([800.0, 0.0]), off), [5.0, 41.57])


@pytest.mark.parametrize("rows", [1, 5, 200])
@pytest.mark.parametrize("k", [1, 2, 7, 40])
def test_accumulate_is_the_sequential_sum_from_zero(rows, k):
    """The repulsion terms are summed 0 + t_1 + ... + t_K in column order, in floats, skipping invalid
    entries (what makes an agent's row the same in a table of any width and any number of rows); -0.0
    terms included."""
    rng = np.random.default_rng(k * 1000 + rows)
    tx = rng.normal(0, 1e3, (rows, k)) * rng.choice([1e-12, 1.0, 1e12], (rows, k))
    ty = rng.normal(0, 1, (rows, k))
    tx[:, 0] = -0.0
    valid = rng.uniform(size=(rows, k)) < 0.7
    got = _accumulate(tx, ty, valid)
    for i in range(rows):
        sx = sy = 0.0
        for c in range(k):
            if valid[i, c]:
                sx, sy = sx + float(tx[i, c]), sy + float(ty[i, c])
        assert got[i].tobytes() == np.array([sx, sy]).tobytes()
