"""Corners of the control law (reconswarm/paper/planner.py) against its equations: the virtual leader's
containment wall (eq. 11's form on d = R_c - ‖p - c‖, pushing toward the centre) near and at the centre of a
small disk; an obstacle the agent does not know does not repel it, however close; the neighbour tables'
shared arrays are read-only, and one builder reused over changing neighbours gives fresh tables; coincident
centres and a disk smaller than a metre."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reconswarm.geometry.pairs import pairs_within
from reconswarm.paper.planner import (
    Neighbours,
    NeighbourTables,
    ObstacleView,
    agent_repulsion,
    attraction,
    containment,
    neighbour_table,
    obstacle_repulsion,
)

D_SAFE, D_MAX, PSI = 2.0, 10.0, -65.0


def wall_speed(d: float, r: float) -> float:
    """Eq. (11)'s magnitude on the wall distance d, held at its contact value below d = r."""
    if d > r + D_MAX:
        return 0.0
    return -PSI * (r + D_MAX - max(d, r)) / (D_MAX - D_SAFE)


@pytest.mark.parametrize("dist", [0.05, 0.5, 0.99, 1.5, 3.0])
def test_containment_near_the_centre_of_a_small_disk(dist: float) -> None:
    """R_c = 5 m, r = 1 m: the wall (reaching r + d_max = 11 m in) acts everywhere in the disk; its push is
    the wall's speed at d = R_c - dist, toward the centre, at any distance from it."""
    rc, r = 5.0, 1.0
    c = np.array([3.0, -2.0])
    for ang in (0.3, 2.2, -1.9):
        e = np.array([math.cos(ang), math.sin(ang)])
        p = c + dist * e
        got = containment(p[None], np.array([r]), c[None], rc, D_SAFE, D_MAX, PSI)[0]
        np.testing.assert_allclose(got, -wall_speed(rc - dist, r) * e, rtol=1e-12, atol=1e-12)


def test_containment_at_the_centre_has_no_direction_and_is_zero() -> None:
    c = np.array([[3.0, -2.0]])
    got = containment(c.copy(), np.array([1.0]), c, 5.0, D_SAFE, D_MAX, PSI)
    assert np.isfinite(got).all() and got.tolist() == [[0.0, 0.0]]


def test_an_obstacle_the_agent_does_not_know_does_not_repel() -> None:
    """Two obstacle columns 1 m from the agent (well within d_max): only the known one pushes."""
    r = np.array([1.0])
    ob_d = np.array([[1.0, 1.0]])
    ob_n = np.array([[[1.0, 0.0], [0.0, 1.0]]])
    got = obstacle_repulsion(r, ob_d, ob_n, np.array([[True, False]]), D_SAFE, D_MAX, PSI)
    np.testing.assert_allclose(got, [[wall_speed(1.0, 1.0), 0.0]], rtol=1e-12)
    none = obstacle_repulsion(r, ob_d, ob_n, np.array([[False, False]]), D_SAFE, D_MAX, PSI)
    assert none.tolist() == [[0.0, 0.0]]


def test_neighbour_tables_share_read_only_radii_and_masks() -> None:
    """Tables of one layout share their radii and validity arrays: a caller cannot write into them (it would
    change every later table)."""
    p = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 6.0], [100.0, 0.0]])
    r = np.array([1.0, 1.5, 2.0, 1.0])
    tables = NeighbourTables()
    a = tables(p, r, pairs_within(p, 40.0), D_MAX)
    b = tables(p + 0.1, r, pairs_within(p + 0.1, 40.0), D_MAX)
    assert a.r is b.r and a.valid is b.valid
    with pytest.raises(ValueError):
        a.r[0, 0] = 9.0
    with pytest.raises(ValueError):
        a.valid[0, 0] = False


def test_coincident_centres_push_along_plus_x_at_the_contact_value() -> None:
    """Two agents on the same point: eq. (11) has no direction there; the push is along +x with the contact
    magnitude |Ψ| d_max / (d_max - d_safe) (never NaN)."""
    p = np.array([[4.0, -3.0]])
    got = agent_repulsion(p, np.array([1.0]), p[:, None, :].copy(), np.array([[2.0]]), np.array([[True]]),
                          D_SAFE, D_MAX, PSI)
    np.testing.assert_allclose(got, [[-PSI * D_MAX / (D_MAX - D_SAFE), 0.0]], rtol=1e-12)


def test_attraction_outside_a_disk_smaller_than_a_metre() -> None:
    """Outside B(p*, R_c) the pull is R_c k_att toward p*, whatever R_c (here 0.5 m, the agent 0.8 m away)."""
    c = np.array([10.0, 10.0])
    e = np.array([0.6, -0.8])
    got = attraction((c + 0.8 * e)[None], c, np.zeros((1, 2)), 0.1, 0.5)[0]
    np.testing.assert_allclose(got, -0.5 * 0.1 * e, rtol=1e-12)


def test_one_table_builder_over_changing_neighbours_equals_a_fresh_one_each_time() -> None:
    """NeighbourTables keeps its layout while the pairs within d_max,ij stay the same; when they change (here
    every few steps, including a single pair and none) it must give what a fresh table gives."""
    rng = np.random.default_rng(5)
    r = np.array([1.0, 1.5, 2.0, 1.0, 0.5])
    tables = NeighbourTables()
    for step in range(12):
        if step in (3, 4):  # a single pair: agents 0 and 1 close, the rest far apart
            p = np.array([[0.0, 0.0], [4.0, 0.0], [100.0, 0.0], [200.0, 0.0], [300.0, 0.0]])
        elif step == 5:
            p = np.array([[0.0, 0.0], [100.0, 0.0], [200.0, 0.0], [300.0, 0.0], [400.0, 0.0]])
        else:
            p = rng.uniform(0.0, 25.0, (5, 2))
        pairs = pairs_within(p, 40.0)
        got, want = tables(p, r, pairs, D_MAX), neighbour_table(p, r, pairs, D_MAX)
        assert got.p.tolist() == want.p.tolist() and got.r.tolist() == want.r.tolist(), step
        assert got.valid.tolist() == want.valid.tolist(), step
        if step in (3, 4):
            assert got.valid.sum() == 2 and got.r[0, 0] == 1.5 and got.r[1, 0] == 1.0


def test_an_empty_table_is_one_per_row_count_holds_nothing_and_cannot_be_written() -> None:
    """Neighbours.empty and ObstacleView.empty (every plan without a peer or obstacle near asks for one): shared,
    so read-only; the stacked table of empty and non-empty rows is a fresh, writable one."""
    nb, ob = Neighbours.empty(1), ObstacleView.empty(3)
    assert nb is Neighbours.empty(1) and ob is ObstacleView.empty(3) and nb is not Neighbours.empty(2)
    assert (nb.p.shape, nb.r.shape, nb.valid.shape) == ((1, 0, 2), (1, 0), (1, 0))
    assert (ob.d.shape, ob.n.shape, ob.valid.shape) == ((3, 0), (3, 0, 2), (3, 0))
    for a in (nb.p, nb.r, nb.valid, ob.d, ob.n, ob.valid):
        with pytest.raises(ValueError, match="read-only"):
            a[...] = 0
    one = Neighbours(np.ones((1, 1, 2)), np.ones((1, 1)), np.ones((1, 1), dtype=bool))
    both = Neighbours.stack([nb, one])
    assert both.valid.tolist() == [[False], [True]] and both.p.flags.writeable
