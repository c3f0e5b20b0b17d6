"""Who an agent hears and waits for (agent/neighbours.py), case by case: a peer with no beacon of the tick before
is placed where it was last seen (its start only if never seen), on both axes and up to the bound included;
the first tick of an agent joining waits for everyone; intruders by their distance on both axes; realtime's
peers heard lately; what the runtime still waits for; the cells recomputed wherever the agent moves."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from agent.neighbours import Neighbourhood
from reconswarm.net.timing import TIMING
from reconswarm.net.trust.membership import Policy
from reconswarm.net.wire.cells import CellGrid
from reconswarm.plant import unicycle
from reconswarm.scenario.model import load
from tests.support import PAPER, beacon

S = load(PAPER)
DT = S.meta.dt_s


def _acting(p: tuple[float, float] = (0.0, 64.0), k: int = 4) -> Neighbourhood:
    """Agent 1 at p since the mission's start (ticks 0..k), its cells known; a plain grid: matters within 12 m."""
    nb = Neighbourhood(S, 1)
    nb.grid = CellGrid(width_m=16.0, reach_m=10.0, step_m=1.0)  # (matter_m = 12 m, reach 10 m: exact squares)
    for kk in range(k + 1):
        nb.on_state(kk, p)
    return nb


def test_a_peer_back_without_a_beacon_is_placed_where_it_was_last_seen_not_at_its_start() -> None:
    nb = _acting()
    for peer in (2, 3, 4, 5, 6):
        nb.peer_joined(peer, acting=True)
    nb.start[2] = (0.0, 64.0 + 5.0)  # its start is near us, but it was last seen 100 m away: not waited for
    nb.start[3] = (500.0, 500.0)  # never seen: placed at its start, far away
    last_seen = {2: beacon(2, 1, 100.0, 64.0),
                 4: beacon(4, 2, 0.0, 64.0 + 12.0),  # exactly at the bound (12 m): waited for
                 5: beacon(5, 2, 0.0, 64.0 + 12.5),  # just beyond, along the y axis
                 6: beacon(6, 2, 0.0, 65.0)}  # seen here once; its beacon of k-1 says it is elsewhere now
    prev = {6: beacon(6, 4, 50.0, 64.0)}  # agent 6 has its beacon of k-1: placed by it (50 m away)
    assert nb.wait_set(5, range(1, 11), prev, last_seen) == frozenset({4})


def test_realtime_places_a_peer_where_it_was_last_seen_and_never_seen_at_its_start() -> None:
    nb = _acting()
    nb.start[2], nb.start[3] = (0.0, 70.0), (0.0, 70.0)  # both start near us
    last_seen = {2: beacon(2, 3, 0.0, 164.0)}  # agent 2 was seen far away since
    assert nb.near_now((0.0, 64.0), {2, 3}, last_seen) == {3}


def test_an_agents_first_tick_joining_a_mission_under_way_waits_for_every_peer() -> None:
    nb = Neighbourhood(S, 1)
    nb.on_state(1, (0.0, 0.0))
    assert nb.listen is None  # (every cell until our first command)
    assert nb.wait_set(1, range(1, 11), {}, {}) == frozenset(range(2, 11))


def test_intruders_are_within_reach_on_both_axes_the_bound_included() -> None:
    nb = _acting()
    assert nb.wait_set(4, [], {}, {}) == frozenset()
    fresh = {2: beacon(2, 4, 0.0, 74.0),  # 10 m above: within reach (its edge)
             3: beacon(3, 4, 0.0, 74.5),  # beyond it
             4: beacon(4, 4, 6.0, 72.0),  # 10 m away on the diagonal
             5: beacon(5, 4, 0.0, -74.0)}  # far below (mirrored)
    assert [b.id for b in nb.intruders(4, fresh)] == [2, 4]
    assert nb.intruder(4, fresh[2]) and not nb.intruder(4, fresh[3])


def test_realtime_hears_lately_who_spoke_within_a_second_or_three_periods() -> None:
    heard = {2: 6.0, 3: 8.25, 4: 9.0, 5: 9.5}  # (in the order of their times)
    lately_s = Policy.agent(TIMING).lately_s
    assert lately_s == 1.0
    assert Neighbourhood.heard_lately({2, 3, 4, 5}, heard, 10.0, DT, lately_s) == {4, 5}  # 1.0 s ago: still heard
    assert Neighbourhood.heard_lately({2, 3, 4, 5}, heard, 10.0, 0.5, lately_s) == {4, 5}  # 1.5 s: 3 periods of 0.5 s
    assert Neighbourhood.heard_lately({2, 3, 4}, heard, 9.75, 0.5, lately_s) == {3, 4}  # 1.5 s ago: in; 5 is not alive


def test_the_runtime_waits_for_live_peers_that_spoke_in_a_cell_it_hears() -> None:
    nb = _acting()
    inside = nb.grid.cell_of(0.0, 64.0)
    assert inside in (nb.listen or frozenset())
    prev = {2: beacon(2, 4, 1.0, 65.0), 3: beacon(3, 4, 900.0, 900.0), 4: beacon(4, 4, 2.0, 66.0),
            5: beacon(5, 4, 3.0, 63.0)}
    # 2: will come; 3: in a cell we do not hear; 4: not alive; 5: waited for already
    assert nb.also_heard({2, 3, 5}, prev, {}, frozenset({5})) == 1
    assert nb.also_heard({2, 3, 5}, prev, {2: prev[2]}, frozenset({5})) == 0  # (its beacon is in)


def test_the_cells_follow_the_agent_wherever_it_goes() -> None:
    nb = _acting((-500.0, -500.0), k=0)
    for k, p in enumerate([(500.0, -500.0), (500.0, 500.0), (500.0, 500.5), (-500.0, 500.0)], start=1):
        nb.on_state(k, p)
        nb.after_command(k)
        assert nb.listen == nb.grid.listen_cells(*p)


def test_the_virtual_leader_listens_everywhere_even_after_a_command() -> None:
    nb = Neighbourhood(S.with_planner("virtual-leader"), 1)
    nb.on_state(0, (0.0, 0.0))
    assert nb.after_command(0) is None and nb.listen is None


def test_ticks_older_than_four_are_forgotten() -> None:
    nb = _acting(k=10)
    nb.prune(10)
    assert sorted(nb.own) == [6, 7, 8, 9, 10]


def test_an_intruder_is_explained_with_the_speed_bound() -> None:
    nb = Neighbourhood(S, 1)
    v = nb.grid.step_m / DT
    assert f"faster than the speed bound {v:g} m/s" in nb.unexpected(beacon(2, 7, 0.0, 0.0))
    assert v > 100.0  # (m/s: not a step in metres)


def test_a_peers_start_is_its_head_point() -> None:
    turned = dataclasses.replace(S, agents=tuple(
        dataclasses.replace(a, heading_rad=0.7, head_offset_m=1.5) if a.id == 2 else a for a in S.agents))
    nb = Neighbourhood(turned, 1)
    a2 = turned.agents[turned.agent_index(2)]
    want = unicycle.head_point(np.array([a2.start_m]), np.array([0.7]), np.array([1.5]))[0]
    assert nb.start[2] == (float(want[0]), float(want[1]))
    assert abs(math.hypot(*(want - a2.start_m)) - 1.5) < 1e-12 and want[1] > a2.start_m[1]
