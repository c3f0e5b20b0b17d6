"""A lost robot beside an obstacle (reconswarm/paper/blocked.py): grouped when the gap is too narrow to pass,
and an agent caught in the pocket between them gets out and on to its slot."""

from __future__ import annotations

import numpy as np

from agent.brain import AgentBrain, Peer
from reconswarm.geometry.plane import distance_to_polygon, norm2, points_inside_hull
from reconswarm.paper.blocked import blocked_hulls, disc_polygon, inside, lost_groups, merged_hulls, pass_gap_m
from reconswarm.scenario.model import Scenario, load
from tests.support import PAPER

SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
DIAMOND = np.array([[300.0, -45.0], [345.0, 0.0], [300.0, 45.0], [255.0, 0.0]])


def test_disc_polygon_holds_the_disc() -> None:
    poly = disc_polygon(3.0, -2.0, 4.0)
    ring = np.stack([3.0 + 4.0 * np.cos(a := np.linspace(0, 2 * np.pi, 721)), -2.0 + 4.0 * np.sin(a)], axis=1)
    d, _ = distance_to_polygon(ring, poly)
    assert (d <= 1e-9).all()  # every point of the circle is inside or on the polygon
    assert norm2(poly - [3.0, -2.0]).max() < 4.0 * 1.02  # and the polygon hugs it


def test_a_disc_is_grouped_with_the_hull_it_is_too_close_to() -> None:
    gap = pass_gap_m(4.0, 10.0)  # 28 m
    assert gap == 28.0
    near = np.array([[10.0 + 2.0 + 27.0, 5.0, 2.0]])  # its surface 27 m from the square's face: grouped
    far = np.array([[10.0 + 2.0 + 29.0, 5.0, 2.0]])  # 29 m: the agent passes between them
    hulls, absorbed = blocked_hulls([SQUARE], near, gap)
    assert absorbed.tolist() == [True] and len(hulls) == 1
    assert points_inside_hull(np.array([[38.0, 5.0], [5.0, 5.0], [25.0, 5.0]]), hulls[0]).all()
    hulls, absorbed = blocked_hulls([SQUARE], far, gap)
    assert absorbed.tolist() == [False] and len(hulls) == 1 and np.array_equal(hulls[0], SQUARE)


def test_hulls_are_never_grouped_with_each_other_only_through_a_lost_robot() -> None:
    other = SQUARE + np.array([15.0, 0.0])  # 5 m from the square: close, but obstacles alone are left as they are
    hulls, absorbed = blocked_hulls([SQUARE, other], np.zeros((0, 3)), 28.0)
    assert len(hulls) == 2 and absorbed.size == 0
    lone = np.array([[200.0, 200.0, 3.0], [12.5, 30.0, 2.0]])  # one far away; one near both squares
    hulls, absorbed = blocked_hulls([SQUARE, other], lone, 28.0)
    assert absorbed.tolist() == [False, True] and len(hulls) == 1  # both squares and the disc: one hull
    two = np.array([[100.0, 0.0, 3.0], [120.0, 0.0, 3.0]])  # two lost robots 14 m apart: one obstacle
    hulls, absorbed = blocked_hulls([], two, 28.0)
    assert absorbed.tolist() == [True, True] and len(hulls) == 1


def _drive(s: Scenario, starts: dict[int, tuple[float, float]], dead: Peer, as_lost: bool, ticks: int
           ) -> dict[int, np.ndarray]:
    """Agents by the diamond under their brains' commands, p_dot = u (no actuator limits), for `ticks` steps;
    robot 3 dead where it stopped, given to each brain as lost (or as a neighbour). Returns their tracks."""
    brains = {a: AgentBrain(s, a) for a in starts}
    for b in brains.values():
        b.known.merge("diamond", DIAMOND)
        b.rev += 1  # (as a scan that found it would)
    p = {a: np.array(xy) for a, xy in starts.items()}
    track = {a: [q.copy()] for a, q in p.items()}
    r = {a: s.agents[s.agent_index(a)].radius_m for a in starts}
    for k in range(ticks):
        u = {}
        for a, b in brains.items():
            peers = [Peer(o, float(p[o][0]), float(p[o][1]), r[o]) for o in brains if o != a]
            u[a], _ = b.tick(k, p[a].copy(), {}, peers if as_lost else [*peers, dead], [], None,
                             [dead] if as_lost else [])
        for a in brains:
            p[a] = p[a] + s.meta.dt_s * u[a]
            track[a].append(p[a].copy())
    return {a: np.array(t) for a, t in track.items()}


def test_agents_caught_between_a_dead_robot_and_the_diamond_get_out() -> None:
    """The paper's mission with agent 3 killed at t = 40 s: robot 3 stops by the diamond's lower vertex and
    agents 6, 7 and 10 stood still on the diamond's lower-left face, 590 m from their slots, to the end."""
    s = load(PAPER)
    dead = Peer(3, 283.8665541598868, -46.63689867943773, s.agents[s.agent_index(3)].radius_m)
    starts = {6: (259.75354706885906, -23.406071674483222), 7: (271.2848947074212, -36.45158833842402),
              10: (246.13080694032445, -11.375989582471485)}  # where they stood at t = 60 s, and to the end
    ticks = round(60.0 / s.meta.dt_s)

    stuck = _drive(s, starts, dead, as_lost=False, ticks=ticks)  # robot 3 as a neighbour: the pocket holds
    assert all(norm2(t[-1] - t[-200]) < 0.05 and t[-1, 0] < 300.0 for t in stuck.values())

    freed = _drive(s, starts, dead, as_lost=True, ticks=ticks)  # robot 3 lost: one obstacle with the diamond
    assert all(t[-1, 0] > 400.0 for t in freed.values())  # past the diamond, on their way to their slots
    for a, t in freed.items():  # never touching robot 3, the diamond or each other
        ra = s.agents[s.agent_index(a)].radius_m
        assert (norm2(t - [dead.px, dead.py]) - dead.radius - ra).min() > 0.0
        assert (distance_to_polygon(t, DIAMOND)[0] - ra).min() > 0.0
        for o, q in freed.items():
            if o > a:
                assert (norm2(t - q) - ra - s.agents[s.agent_index(o)].radius_m).min() > 0.0


def test_a_group_made_around_the_agent_is_left_apart_and_the_agent_is_not_thrown_out_of_it() -> None:
    """Under a flood the world counted every agent gone for a while: each agent's peers all lost at once, six of
    them in a ring 15 m around it are one group (9.8 m apart, closer than the pass gap) whose hull holds the
    agent. Merged, it is pushed out at the repulsion's contact value (metres a tick, through the ring); left
    apart, the ring's robots are neighbours and it moves at cruise speed, never nearer any than d_safe."""
    s = load(PAPER)
    me = s.agents[0].id
    r = s.agents[0].radius_m
    centre = np.array([100.0, 0.0])
    ring = [Peer(100 + j, float(centre[0] + 15.0 * np.cos(a)), float(centre[1] + 15.0 * np.sin(a)), r)
            for j, a in enumerate(np.linspace(0.0, 2 * np.pi, 6, endpoint=False) + 0.3)]
    discs = np.array([[b.px, b.py, b.radius] for b in ring])
    groups = lost_groups([], discs, pass_gap_m(r, s.planner.d_max_m))
    assert len(groups) == 1 and inside(groups, centre) == (0,)
    assert merged_hulls([], len(ring), groups, (0,))[1].tolist() == [False] * 6  # all stay neighbours
    assert len(merged_hulls([], len(ring), groups)[0]) == 1  # (merged: one obstacle of all six)

    brain = AgentBrain(s, me)
    p = centre.copy()
    u, _ = brain.tick(0, p.copy(), {}, [], [], None, ring)
    assert float(norm2(u)) <= s.planner.k_att * s.planner.target_radius_m + 1e-9  # at most the cruise speed
    closest = np.inf
    for k in range(1, 200):
        p = p + s.meta.dt_s * u
        closest = min(closest, min(float(norm2(p - [b.px, b.py])) - b.radius - r for b in ring))
        u, _ = brain.tick(k, p.copy(), {}, [], [], None, ring)
    assert closest > s.planner.d_safe_m


def test_inside_is_the_head_point_in_the_hull_not_a_body_touching_it() -> None:
    """The pocket's agents (above) touch the merged hull as they slide along it: they must keep it."""
    g = lost_groups([SQUARE], np.array([[20.0, 5.0, 2.0]]), 28.0)
    assert inside(g, np.array([5.0, 5.0])) == (0,)
    assert inside(g, np.array([5.0, -0.5])) == ()  # 0.5 m outside: a body of radius 2 overlaps, still merged
