"""Corners of the control law (reconswarm/paper/planner.py) against its equations: the virtual leader's
containment wall (eq. 11's form on d = R_c - ‖p - c‖, pushing toward the centre) near and at the centre of a
small disk; an obstacle the agent does not know does not repel it, however close; the neighbour tables'
shared arrays are read-only."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reconswarm.geometry.pairs import pairs_within
from reconswarm.paper.planner import NeighbourTables, containment, obstacle_repulsion

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
