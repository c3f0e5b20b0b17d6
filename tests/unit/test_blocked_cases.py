"""Lost robots as obstacles (reconswarm/paper/blocked.py), case by case: what counts as too close to pass
(surface to surface, strictly below the gap), which members a group joins, degenerate known hulls (a point, a
segment), and which groups an agent inside one keeps apart."""

from __future__ import annotations

import numpy as np
import pytest

from reconswarm.geometry.plane import distance_to_polygon, points_inside_hull
from reconswarm.paper.blocked import lost_groups, merged_hulls

GAP = 28.0  # pass_gap_m(4, 10): an agent of radius 4 with d_max 10
TRIANGLE = np.array([[0.0, 0.0], [100.0, 0.0], [50.0, 100.0]])  # counter-clockwise


def _pairs(groups: list) -> list[tuple[tuple[int, ...], tuple[int, ...]]]:
    return [(g.discs, g.hulls) for g in groups]


@pytest.mark.parametrize(("centres_m", "grouped"), [(34.99, True), (35.0, False), (35.01, False)])
def test_two_lost_robots_are_too_close_when_their_surfaces_are_nearer_than_the_gap(centres_m: float,
                                                                                   grouped: bool) -> None:
    # Radii 5 and 2: the gap between their surfaces is centres - 7; at exactly 28 m an agent passes.
    discs = np.array([[0.0, 0.0, 5.0], [centres_m, 0.0, 2.0]])
    assert _pairs(lost_groups([], discs, GAP)) == ([((0, 1), ())] if grouped else [])
    # The same with the radii the other way round (each disc's own radius counts once).
    swapped = np.array([[0.0, 0.0, 2.0], [centres_m, 0.0, 5.0]])
    assert _pairs(lost_groups([], swapped, GAP)) == ([((0, 1), ())] if grouped else [])


def test_a_lost_robot_joins_the_one_it_is_near_not_its_neighbour_in_the_list() -> None:
    # Robot 0 is near robot 2 only; robot 1 is far from both.
    discs = np.array([[0.0, 0.0, 1.0], [500.0, 0.0, 1.0], [10.0, 0.0, 1.0]])
    groups = lost_groups([], discs, GAP)
    assert _pairs(groups) == [((0, 2), ())]
    holds = points_inside_hull(np.array([[0.0, 0.0], [10.0, 0.0], [5.0, 0.0], [500.0, 0.0]]), groups[0].hull)
    assert holds.tolist() == [True, True, True, False]


def test_a_chain_of_lost_robots_is_one_group_in_the_order_of_its_first_disc() -> None:
    # 0 - 3 - 1 a chain (20 m apart), 2 alone; a second pair 4 - 5 far away.
    discs = np.array([[0.0, 0.0, 1.0], [40.0, 0.0, 1.0], [300.0, 300.0, 1.0], [20.0, 0.0, 1.0],
                      [-400.0, 0.0, 1.0], [-420.0, 0.0, 1.0]])
    assert _pairs(lost_groups([], discs, GAP)) == [((0, 1, 3), ()), ((4, 5), ())]


def test_the_gap_to_a_known_hull_is_from_the_robots_surface_strictly_below() -> None:
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    for x_m, grouped in [(10.0 + 3.0 + 27.99, True), (10.0 + 3.0 + 28.0, False)]:
        discs = np.array([[x_m, 5.0, 3.0]])
        assert _pairs(lost_groups([square], discs, GAP)) == ([((0,), (0,))] if grouped else [])


def test_a_triangle_is_measured_as_a_polygon_not_as_a_segment() -> None:
    # 20 m beyond the vertex (100, 0): near the triangle, far from the segment between its first and last vertex.
    discs = np.array([[120.0, 0.0, 1.0]])
    assert distance_to_polygon(discs[:, :2], TRIANGLE)[0][0] == pytest.approx(20.0)
    assert _pairs(lost_groups([TRIANGLE], discs, GAP)) == [((0,), (0,))]


def test_a_known_hull_of_one_point() -> None:
    point = np.array([[50.0, 50.0]])
    near = np.array([[50.0 + 2.0 + 27.5, 50.0, 2.0]])  # its surface 27.5 m from the point
    far = np.array([[50.0, 50.0 + 2.0 + 28.5, 2.0]])
    assert _pairs(lost_groups([point], near, GAP)) == [((0,), (0,))]
    assert _pairs(lost_groups([point], far, GAP)) == []


def test_a_known_hull_of_two_points_is_a_segment() -> None:
    o = np.array([200.0, 300.0])  # (away from the origin: positions are taken relative to the segment's start)
    seg = o + np.array([[0.0, 0.0], [100.0, 0.0]])

    def grouped(x_m: float, y_m: float, r_m: float) -> bool:
        return _pairs(lost_groups([seg], np.array([[o[0] + x_m, o[1] + y_m, r_m]]), GAP)) == [((0,), (0,))]

    assert grouped(50.0, 30.0, 3.0)  # beside the middle: 30 m from its line, 50 m and more from both ends
    assert grouped(125.0, 0.0, 1.0)  # past an end: 25 m beyond it (gap 24), measured to that end
    assert not grouped(130.0, 0.0, 1.0)  # 29 m of gap past the far end: passable
    assert not grouped(-40.0, 0.0, 1.0)  # before the near end, on the segment's line: 39 m from it
    assert grouped(-25.0, 0.0, 1.0)
    # The radius counts from the surface: 30.99 m from the line with radius 3 is 27.99 (grouped), with radius 2
    # 28.99 (not).
    assert grouped(50.0, 30.99, 3.0) and not grouped(50.0, 30.99, 2.0)


def test_a_segment_shorter_than_a_metre_is_measured_to_its_nearer_end() -> None:
    short = np.array([[0.0, 0.0], [0.5, 0.0]])
    discs = np.array([[0.5 + 28.5, 0.0, 1.0]])  # 28.5 m from the end (0.5, 0) -> gap 27.5; 29 m from (0, 0)
    assert _pairs(lost_groups([short], discs, GAP)) == [((0,), (0,))]


def test_a_segment_of_two_equal_points_is_that_point() -> None:
    dot = np.array([[5.0, 5.0], [5.0, 5.0]])
    discs = np.array([[5.0, 30.0, 1.0], [5.0, 300.0, 1.0], [-300.0, 5.0, 1.0]])  # 25 m away (gap 24), two far
    assert _pairs(lost_groups([dot], discs, GAP)) == [((0,), (0,))]


def test_an_empty_known_hull_is_skipped_and_the_next_ones_still_count() -> None:
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    discs = np.array([[20.0, 5.0, 1.0]])
    groups = lost_groups([np.zeros((0, 2)), square], discs, GAP)
    assert _pairs(groups) == [((0,), (1,))]


def test_groups_an_agent_is_inside_stay_apart_and_the_others_are_merged() -> None:
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    far_square = square + 1000.0
    discs = np.array([[20.0, 5.0, 1.0], [1020.0, 1005.0, 1.0], [-700.0, 0.0, 1.0]])
    groups = lost_groups([square, far_square], discs, GAP)
    assert _pairs(groups) == [((0,), (0,)), ((1,), (1,))]
    hulls, absorbed = merged_hulls([square, far_square], 3, groups, apart=(0,))
    assert absorbed.dtype == np.bool_ and absorbed.tolist() == [False, True, False]
    assert len(hulls) == 2 and np.array_equal(hulls[0], square)  # group 0 as it was: its hull and its robot apart
    assert np.array_equal(hulls[1], groups[1].hull)  # group 1 merged all the same
    hulls, absorbed = merged_hulls([square, far_square], 3, groups)
    assert absorbed.tolist() == [True, True, False] and len(hulls) == 2
    assert [np.array_equal(h, g.hull) for h, g in zip(hulls, groups, strict=True)] == [True, True]


def test_a_merged_group_holds_every_lost_robot_whole() -> None:
    discs = np.array([[0.0, 0.0, 4.0], [15.0, 3.0, 2.5]])
    (group,) = lost_groups([], discs, GAP)
    a = np.linspace(0.0, 2.0 * np.pi, 721)
    for x, y, r in discs:
        circle = np.stack([x + r * np.cos(a), y + r * np.sin(a)], axis=1)
        d, _ = distance_to_polygon(circle, group.hull)
        assert (points_inside_hull(circle, group.hull) | (d <= 1e-9)).all()
