"""Cells of the key space (reconswarm/net/wire/cells.py), case by case: the speed bound (the world's limit, however
small, else the planner's with the stall push added), the reach set by the robots' bodies when they reach
farther than a link, a peer that may matter by its distance on both axes, and cell names in keys."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from reconswarm.net.wire.cells import CellGrid, chunk_cell, speed_bound_mps
from reconswarm.paper.link import HYSTERESIS_M
from reconswarm.scenario.model import load

S = load(Path(__file__).resolve().parents[2] / "deploy" / "scenarios" / "paper.toml")


def test_the_speed_bound_is_the_worlds_limit_however_small_else_the_planners_with_the_push() -> None:
    slow = dataclasses.replace(S, world=dataclasses.replace(S.world, max_speed_mps=0.5))
    assert speed_bound_mps(slow) == 0.5
    pushed = dataclasses.replace(S, planner=dataclasses.replace(S.planner, perturbation_mps=3.0))
    p = pushed.planner
    assert speed_bound_mps(pushed) == p.target_radius_m * p.k_att + 2.0 * abs(p.psi_mps) + 3.0


def test_the_reach_is_the_bodies_when_they_reach_farther_than_a_link() -> None:
    short = dataclasses.replace(S, planner=dataclasses.replace(S.planner, link_range_m=1.0))
    grid = CellGrid.for_scenario(short)
    r_max = float(short.radii.max())
    assert 2.0 * r_max + short.planner.d_max_m > 1.0 + HYSTERESIS_M
    assert grid.reach_m == 2.0 * r_max + short.planner.d_max_m
    assert CellGrid.for_scenario(S).reach_m == S.planner.link_range_m + HYSTERESIS_M


def test_a_peer_may_matter_by_its_distance_on_both_axes() -> None:
    grid = CellGrid(width_m=100.0, reach_m=50.0, step_m=5.0)  # matters within 60 m
    own = (100.0, 200.0)
    assert grid.may_matter(own, (100.0, 260.0)) and not grid.may_matter(own, (100.0, 260.5))
    assert grid.may_matter(own, (40.0, 200.0)) and not grid.may_matter(own, (39.5, 200.0))
    assert grid.may_matter(own, (100.0 + 36.0, 200.0 - 48.0)) and not grid.may_matter(own, (137.0, 151.0))
    assert not grid.may_matter((0.0, 0.0), (1e308, -1e308))  # (beyond the float range: inf, not an error)


def test_cell_names_take_at_most_nine_digits_and_a_bad_one_is_named() -> None:
    assert chunk_cell("123456789_-987654321") == (123456789, -987654321)
    with pytest.raises(ValueError, match="bad cell '1234567890_0'"):
        chunk_cell("1234567890_0")
    with pytest.raises(ValueError, match="bad cell '3x4'"):
        chunk_cell("3x4")
    assert CellGrid(10.0, 5.0, 1.0).cell_of(-0.5, 19.99) == (-1, 1)  # (floor: negative coordinates too)
