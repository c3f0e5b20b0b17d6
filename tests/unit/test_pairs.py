"""Pairs of nearby points (reconswarm.geometry.pairs): the dense and the grid search give exactly the pairs within
the radius, sorted, and the Verlet list gives a fresh search's pairs, order and distances."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.geometry.pairs import NearPairs, pairs_and_distances, pairs_within


def brute_pairs(p: np.ndarray, radius: float) -> set[tuple[int, int]]:
    n = p.shape[0]
    out = set()
    for i in range(n):
        dx = p[i + 1:, 0] - p[i, 0]
        dy = p[i + 1:, 1] - p[i, 1]
        for j in np.flatnonzero(np.sqrt(dx * dx + dy * dy) <= radius):
            out.add((i, i + 1 + int(j)))
    return out


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 260), st.integers(0, 2**32 - 1), st.floats(0.5, 30.0), st.booleans())
def test_pairs_within_dense_and_grid_agree_with_brute_force(n, seed, radius, lattice):
    rng = np.random.default_rng(seed)
    if lattice:  # many pairs exactly at the radius (3-4-5 triangles, axis neighbours)
        p = rng.integers(-20, 20, (n, 2)).astype(np.float64) * 1.0
        radius = float(rng.choice([1.0, 5.0, 10.0]))
    else:
        p = rng.uniform(-100, 100, (n, 2))
    got = pairs_within(p, radius)
    assert got.dtype == np.int64 and got.shape[1] == 2
    assert [tuple(x) for x in got.tolist()] == sorted(brute_pairs(p, radius))  # sorted, i < j, exact set


def test_pairs_within_same_set_across_the_dense_grid_threshold():
    rng = np.random.default_rng(5)
    p = rng.integers(-15, 15, (200, 2)).astype(np.float64)
    r = 5.0
    big = pairs_within(p, r)  # grid path (N > 96)
    # The dense path on every subset of <= 96 points gives the restriction of the same set.
    for lo in (0, 60, 104):
        sub = p[lo:lo + 96]
        small = {(i + lo, j + lo) for i, j in pairs_within(sub, r).tolist()}
        want = {(i, j) for i, j in big.tolist() if lo <= i < lo + 96 and lo <= j < lo + 96}
        assert small == want
    assert pairs_within(p[:1], 10.0).shape == (0, 2)
    assert pairs_within(rng.uniform(0, 1e6, (150, 2)), 1e-3).shape == (0, 2)


def test_pairs_within_grid_with_a_huge_extent_and_unknown_points():
    """Coordinates spread over 1e12 m with a 1 m radius (coarser cells than the radius, so the cell keys
    fit) and rows of NaN (an unknown state: in no pair) give exactly the brute-force pairs."""
    rng = np.random.default_rng(11)
    p = np.concatenate([rng.uniform(-5e11, 5e11, (150, 2)), rng.uniform(0, 3, (60, 2))])
    p[[3, 170, 200]] = np.nan
    got = [tuple(x) for x in pairs_within(p, 1.0).tolist()]
    fin = np.isfinite(p).all(axis=1)
    want = sorted((i, j) for i, j in brute_pairs(np.where(fin[:, None], p, 0.0), 1.0) if fin[i] and fin[j])
    assert got == want and len(want) > 50


@pytest.mark.parametrize("n", [40, 300])
def test_near_pairs_equal_a_fresh_search_every_step(n):
    """The Verlet list gives, step after step, exactly the pairs, order and distances of a fresh search,
    also across its rebuilds (points moving up to 3 m a step against a 2.5 m skin)."""
    rng = np.random.default_rng(n)
    p = rng.uniform(0, 150, (n, 2))
    near = NearPairs(12.0, 5.0)
    for _ in range(60):
        got, got_d = near(p)
        want, want_d = pairs_and_distances(p, 12.0)
        assert got.tolist() == want.tolist()
        assert got_d.tobytes() == want_d.tobytes()
        p = p + rng.uniform(-1.5, 1.5, (n, 2)) * (rng.uniform(size=(n, 1)) < 0.2)
