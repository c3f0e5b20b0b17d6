"""Cells of the key space: a peer that can matter is always in a cell the agent listens to."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.net.wire.cells import CellGrid, cell_chunk, chunk_cell, speed_bound_mps
from reconswarm.scenario.model import load

PAPER = Path(__file__).resolve().parents[2] / "deploy" / "scenarios" / "paper.toml"
GRID = CellGrid.for_scenario(load(PAPER))
coord = st.floats(-5000, 5000, allow_nan=False)


def test_paper_grid_is_wider_than_reach_plus_two_steps():
    s = load(PAPER)
    v = speed_bound_mps(s)
    assert v == pytest.approx(80 * 0.08 + 2 * 65.0)
    assert GRID.width_m == pytest.approx(GRID.reach_m + 2 * v * 0.05)
    assert GRID.reach_m == pytest.approx(42.0)


@settings(max_examples=400, deadline=None)
@given(coord, coord, st.floats(0, 1), st.floats(0, 2 * math.pi), st.floats(0, 1), st.floats(0, 2 * math.pi))
def test_a_peer_that_can_matter_publishes_in_a_listened_cell(x, y, r1, a1, r2, a2):
    """We listen from tick k on to the cells around p_i(k). A peer within reach + 2 V dt of p_i(k) at k (one we
    wait for at k+1) moves at most V dt: its beacon of tick k+1 is published in a cell we listen to. (A peer
    within reach of p_i(k+1) is within reach + V dt of p_i(k): covered too.)"""
    g = GRID
    d = (g.reach_m + 2 * g.step_m) * r1
    px, py = x + d * math.cos(a1), y + d * math.sin(a1)
    qx, qy = px + g.step_m * r2 * math.cos(a2), py + g.step_m * r2 * math.sin(a2)
    assert g.cell_of(qx, qy) in g.listen_cells(x, y)


@settings(max_examples=200, deadline=None)
@given(coord, coord)
def test_listen_set_is_small(x, y):
    assert 1 <= len(GRID.listen_cells(x, y)) <= 16


def test_may_matter_is_the_two_step_bound():
    g = GRID
    lim = g.reach_m + 2 * g.step_m
    assert g.may_matter((0, 0), (lim, 0))
    assert not g.may_matter((0, 0), (lim + 1e-6, 0))


@pytest.mark.parametrize("c", [(0, 0), (-3, 4), (12, -7), (-1, -1)])
def test_chunk_round_trip(c):
    assert chunk_cell(cell_chunk(c)) == c


@pytest.mark.parametrize("bad", ["", "3", "3_", "_4", "a_b", "3_4_5", "--3_4", "1e3_2", "9999999999_1",
                                 "01_0", "0_-01", "-0_1", "+1_0", "²_1", "1_٣", " 1_2", "1_2\n"])
def test_bad_chunks_are_refused(bad):
    with pytest.raises(ValueError):
        chunk_cell(bad)


def listen_cells_by_cell(g: CellGrid, x: float, y: float) -> frozenset[tuple[int, int]]:
    """Every cell whose square's nearest point to (x, y) is within reach + 3 V dt: the definition, cell by cell."""
    rad, w = g.reach_m + 3 * g.step_m, g.width_m
    out = set()
    for cx in range(math.floor((x - rad) / w) - 2, math.floor((x + rad) / w) + 3):
        for cy in range(math.floor((y - rad) / w) - 2, math.floor((y + rad) / w) + 3):
            nx, ny = min(max(x, cx * w), (cx + 1) * w), min(max(y, cy * w), (cy + 1) * w)
            if (nx - x) ** 2 + (ny - y) ** 2 <= rad * rad:
                out.add((cx, cy))
    return frozenset(out)


@settings(max_examples=400, deadline=None)
@given(coord, coord, st.floats(0, 1), st.floats(0, 2 * math.pi))
def test_the_cells_stay_the_same_within_the_margin(x, y, r, a):
    """listen_cells is the definition; moved by less than listen_margin_m, the cells are the same."""
    g = GRID
    cells = g.listen_cells(x, y)
    assert cells == listen_cells_by_cell(g, x, y)
    m = g.listen_margin_m(x, y)
    assert 0.0 <= m <= g.width_m
    d = max(0.0, m - 1e-6) * r
    assert g.listen_cells(x + d * math.cos(a), y + d * math.sin(a)) == cells


@pytest.mark.parametrize("x", [0.0, 10.0, 25.3, GRID.width_m - 1e-3])
def test_the_margin_is_the_distance_to_the_nearest_change(x):
    """Just past the margin, some way of moving changes the cells (the margin is not a loose bound)."""
    g = GRID
    m = g.listen_margin_m(x, 0.5)
    assert m < g.width_m
    d = 1.01 * m + 1e-6  # (1 % past it: a direction within 8 degrees of the nearest change's crosses it)
    moved = [g.listen_cells(x + d * math.cos(t), 0.5 + d * math.sin(t)) for t in np.linspace(0, 2 * math.pi, 720)]
    assert any(c != g.listen_cells(x, 0.5) for c in moved)
