"""Cells and lockstep wait sets (agent/neighbours.py, and the agent node that uses them), no processes.

The rule under test (ISSUE 8, docs/wire.md "Cells"): a peer can contribute to tick k only within reach
of p_i(k); both move at most V dt a tick, so the peers whose beacon of k-1 lay within reach + 2 V dt of
p_i(k-1) are all tick k can need; the agent listens to the cells within reach + 3 V dt of it, adding the
new ones before its command and dropping the old ones after it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.brain import AgentBrain, Peer
from agent.messages import Output
from agent.neighbours import Cells, Neighbourhood
from reconswarm.net.timing import TIMING
from reconswarm.net.wire import wire
from reconswarm.net.wire.cells import CellGrid
from reconswarm.scenario.model import PlannerKind, load
from tests.support import PAPER, joined, left
from tests.unit.solo import SoloNode

A, B, C = 1, 2, 3
HEAD = {A: (0.0, 0.0), B: (30.0, 0.0), C: (200.0, 0.0)}  # head points at tick 0 (heading 0, l = 0.5)
S = dataclasses.replace(load(PAPER), agents=tuple(
    dataclasses.replace(a, start_m=(HEAD[a.id][0] - 0.5, HEAD[a.id][1])) if a.id in HEAD else a
    for a in load(PAPER).agents))
G = CellGrid.for_scenario(S)
WAIT = G.reach_m + 2 * G.step_m  # 55.64 m in the paper scenario
DT = S.meta.dt_s
RADIUS = {a.id: a.radius_m for a in S.agents}
ALIVE = (A, B, C)


def beacon(aid: int, k: int, px: float, py: float) -> wire.Beacon:
    return wire.Beacon(aid, k, k * DT, px, py, RADIUS[aid], 0)


def state(k: int, px: float, py: float) -> wire.State:
    return wire.State(A, k, k * DT, px, py, 0.0, px, py)


def clock(k: int, alive: tuple[int, ...] = ALIVE) -> wire.Clock:
    return wire.Clock(k, k * DT, alive)


def node_with(*peers: int) -> SoloNode:
    node = SoloNode(S, A, 0.0)
    node.step([joined(A), *(joined(p) for p in peers)], 0.0)
    return node


def cmds(out: list[Output]) -> list[wire.Cmd]:
    return [o for o in out if isinstance(o, wire.Cmd)]


def alone(k: int, p: tuple[float, float], peers: list[Peer] | None = None) -> tuple[float, float]:
    brain = AgentBrain(S, A)
    u, _ = brain.tick(k, np.array(p), {}, peers or [], [])
    return brain.inputs(u, 0.0)  # the command as sent: (v, ω) at the state's heading


# ----------------------------------------------------------------------------------------- the wait set

def test_wait_set_is_the_live_peers_near_us_at_k_minus_1() -> None:
    nb = Neighbourhood(S, A)
    nb.on_state(4, (10.0, 0.0))
    nb.after_command(4)
    prev = {B: beacon(B, 4, 10.0 + WAIT, 0.0), C: beacon(C, 4, 10.0, WAIT + 0.01)}
    assert nb.wait_set(5, ALIVE, prev, {}) == {B}  # C is 0.01 m too far: it cannot be within reach at 5
    # Fixed for the tick once computed (a beacon of k-1 coming later does not change whom k waits for) ...
    assert nb.wait_set(5, ALIVE, {**prev, C: beacon(C, 4, 10.0, 0.0)}, {}) == {B}
    # ... but a peer whose token goes is no longer waited for.
    assert nb.wait_set(5, (A, C), prev, {}) == frozenset()
    # A live peer with no beacon of k-1 (it is out of our cells) is not waited for ...
    assert nb.wait_set(6, ALIVE, {}, {B: beacon(B, 2, 10.0, 0.0)}) == frozenset()


def test_at_tick_0_and_for_a_peer_that_joined_again_its_held_position_counts() -> None:
    nb = Neighbourhood(S, A)
    nb.own[0] = HEAD[A]
    assert nb.wait_set(0, ALIVE, {}, {}) == {B}  # the scenario's starts: B 30 m away, C 200 m
    nb.on_state(9, (150.0, 0.0))
    nb.after_command(9)
    nb.peer_joined(C, acting=True)  # C's agent restarted: its robot was held at its start (never heard)
    assert nb.wait_set(10, ALIVE, {}, {}) == {C}
    # C's beacon of 10 places it from tick 11 on (far away now: not waited for), whenever it came.
    assert nb.wait_set(11, ALIVE, {C: beacon(C, 10, 500.0, 0.0)}, {}) == frozenset()
    assert nb.wait_set(12, ALIVE, {}, {}) == frozenset()  # (no beacon of 11 from anyone: nobody near)


def test_a_first_tick_mid_mission_waits_for_every_live_peer() -> None:
    """Joining at tick k > 0 (a restarted agent) it knew nobody's position at k-1; it hears every cell until its
    first command, so it waits for every live peer's beacon, as all agents did before the cells."""
    nb = Neighbourhood(S, A)
    assert nb.wait_set(300, ALIVE, {}, {}) == {B, C}


@settings(max_examples=300, deadline=None)
@given(st.floats(-500, 500), st.floats(-500, 500), st.floats(0, 2 * WAIT), st.floats(0, 2 * math.pi),
       st.floats(0, 1), st.floats(0, 2 * math.pi), st.floats(0, 1), st.floats(0, 2 * math.pi))
def test_every_peer_within_reach_at_k_is_waited_for(x, y, d, a, m1, b1, m2, b2) -> None:
    """Whatever both do within the speed bound V between k-1 and k, a peer within reach of p_i(k) at k is in
    the wait set derived from tick k-1."""
    nb = Neighbourhood(S, A)
    own0, peer0 = (x, y), (x + d * math.cos(a), y + d * math.sin(a))
    own1 = (own0[0] + G.step_m * m1 * math.cos(b1), own0[1] + G.step_m * m1 * math.sin(b1))
    peer1 = (peer0[0] + G.step_m * m2 * math.cos(b2), peer0[1] + G.step_m * m2 * math.sin(b2))
    nb.own[4] = own0
    waited = nb.wait_set(5, ALIVE, {B: beacon(B, 4, *peer0)}, {})
    if math.dist(own1, peer1) <= G.reach_m:
        assert B in waited
    # and its beacon of k is published in a cell we listen to from k-1 on
    assert G.cell_of(*peer1) in G.listen_cells(*own0) or math.dist(own0, peer1) > G.reach_m + 3 * G.step_m


def test_the_virtual_leader_waits_for_everyone_and_hears_every_cell() -> None:
    nb = Neighbourhood(S.with_planner(PlannerKind.VIRTUAL_LEADER), A)
    nb.own[4] = (0.0, 0.0)
    assert nb.wait_set(5, ALIVE, {C: beacon(C, 4, 900.0, 0.0)}, {}) == {B, C}
    assert nb.current().listen is None


# ------------------------------------------------------------------------------------------ the cells

def test_a_node_says_the_cells_a_new_session_declares() -> None:
    """Its link and host ask the node (`AgentNode.cells`), not its neighbourhood: every cell until its first
    command, from its start's cell, the cells around its start warm (none under the virtual leader's law)."""
    assert SoloNode(S, A, 0.0).cells() == Cells(G.cell_of(*HEAD[A]), None, G.listen_cells(*HEAD[A]))
    assert SoloNode(S.with_planner(PlannerKind.VIRTUAL_LEADER), A, 0.0).cells().warm == frozenset()


def test_cells_follow_the_agent_new_before_the_command_old_after_it() -> None:
    nb = Neighbourhood(S, A)
    # Every cell until the first command (a restarted agent does not know where its robot is), then around it...
    assert nb.current() == Cells(G.cell_of(*HEAD[A]), None)
    assert nb.on_state(3, HEAD[A]) is None  # (joining at tick 3)
    assert nb.after_command(3) == nb.current() == Cells(G.cell_of(*HEAD[A]), G.listen_cells(*HEAD[A]))
    # ... unless the mission starts (tick 0): around it from its state on, before its beacon.
    nb = Neighbourhood(S, A)
    assert nb.on_state(0, HEAD[A]) == nb.current() == Cells(G.cell_of(*HEAD[A]), G.listen_cells(*HEAD[A]))
    assert nb.after_command(0) is None
    assert nb.on_state(1, HEAD[A]) is None and nb.after_command(1) is None  # nothing moved
    far = (3 * G.width_m + 1.0, 0.0)  # (a jump, to see both sets apart)
    grown = nb.on_state(1, far)
    assert grown == Cells(G.cell_of(*far), G.listen_cells(*HEAD[A]) | G.listen_cells(*far))
    assert nb.after_command(1) == Cells(G.cell_of(*far), G.listen_cells(*far))


def test_the_node_moves_its_cells_before_its_beacon_and_puts_its_set_again_in_a_new_cell() -> None:
    node = node_with()
    pts = ((10.0, 5.0, "diamond"), (11.0, 6.0, "diamond"), (11.0, 4.0, "diamond"))
    node.step([clock(0, (A,)), wire.State(A, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, wire.Scan(A, 0, 0.0, pts))], 0.0)
    assert node.k == 0 and node.brain.rev == 1
    x = G.width_m + 0.5  # tick 1 is in the next cell to the east
    out = node.step([clock(1, (A,)), state(1, x, 0.0)], 0.1)
    kinds = [type(o) for o in out]
    assert kinds == [Cells, wire.ObstacleSet, wire.Beacon, wire.Cmd, Cells]
    moved, again, narrowed = out[0], out[1], out[4]
    assert isinstance(moved, Cells) and isinstance(again, wire.ObstacleSet) and isinstance(narrowed, Cells)
    assert moved.home == (1, 0) and moved.listen == G.listen_cells(0.0, 0.0) | G.listen_cells(x, 0.0)
    assert again.rev == 1 and set(again.obstacles) == {"diamond"}
    assert narrowed.listen == G.listen_cells(x, 0.0)


# ----------------------------------------------------------------------- peers leaving, peers lost

def test_a_live_peer_that_left_is_neither_waited_for_nor_planned_with_at_its_stale_position() -> None:
    node = node_with(B)
    node.step([clock(0), state(0, *HEAD[A]), beacon(B, 0, *HEAD[B])], 0.0)
    assert node.k == 0
    node.step([clock(1), state(1, 0.0, 0.0), beacon(B, 1, WAIT + 1.0, 0.0)], 0.05)  # B moves off (a jump)
    assert node.k == 1
    # Tick 2: B's beacon of 1 was beyond reach + 2 V dt: not waited for; it says nothing more (out of our
    # cells). Our own state jumps next to B's last position: B must not be planned with there.
    out = node.step([clock(2), state(2, WAIT - 3.0, 0.0)], 0.1)
    assert [(c.v_mps, c.omega_radps) for c in cmds(out)] == [alone(2, (WAIT - 3.0, 0.0))]
    assert node.guessed_k == -1


def test_a_lost_peer_stays_an_obstacle_where_it_stopped() -> None:
    node = node_with(B)
    node.step([clock(0), state(0, *HEAD[A]), beacon(B, 0, *HEAD[B])], 0.0)
    node.step([left(B), clock(1, (A, C)), state(1, 20.0, 0.0)], 0.05)
    assert node.k == 1
    out = node.step([clock(2, (A, C)), state(2, 25.0, 0.0)], 0.1)
    assert [(c.v_mps, c.omega_radps) for c in cmds(out)] == [alone(2, (25.0, 0.0), [Peer(B, *HEAD[B], RADIUS[B])])]


# ----------------------------------------------------------------------------------- violations

def test_an_unexpected_peer_within_reach_means_determinism_is_lost() -> None:
    node = node_with(B, C)
    node.step([clock(0), state(0, *HEAD[A]), beacon(B, 0, *HEAD[B])], 0.0)
    assert node.k == 0 and node.guessed_k == -1  # C (200 m away) was not waited for
    # C's beacon of tick 1 is 20 m from us: it crossed 180 m in one tick, far beyond V dt.
    out = node.step([clock(1), state(1, 0.0, 0.0), beacon(B, 1, *HEAD[B]), beacon(C, 1, 20.0, 0.0)], 0.05)
    assert node.k == 1 and node.guessed_k == 1 and any(isinstance(o, wire.Cmd) and o.k == 1 for o in out)


def test_an_unexpected_peer_within_reach_after_we_acted_is_reported_too() -> None:
    node = node_with(B, C)
    node.step([clock(0), state(0, *HEAD[A]), beacon(B, 0, *HEAD[B])], 0.0)
    node.step([clock(1), state(1, 0.0, 0.0), beacon(B, 1, *HEAD[B])], 0.05)
    assert node.k == 1 and node.guessed_k == -1
    node.step([beacon(C, 1, 30.0, 10.0)], 0.06)  # too late: tick 1 was planned without it
    assert node.guessed_k == 1
    node.step([clock(2), state(2, 0.0, 0.0)], 0.1)
    assert node.guessed_k == 1  # the first tick it guessed stays the one said


def test_a_far_unexpected_peer_is_no_violation() -> None:
    node = node_with(B, C)
    node.step([clock(0), state(0, *HEAD[A]), beacon(B, 0, *HEAD[B])], 0.0)
    node.step([clock(1), state(1, 0.0, 0.0), beacon(B, 1, *HEAD[B]), beacon(C, 1, 60.0, 0.0)], 0.05)
    assert node.k == 1 and node.guessed_k == -1  # heard (it is in our cells) but beyond reach: harmless


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 12), st.floats(0.0, 2.0)), max_size=40),
       st.sets(st.integers(1, 12)), st.floats(0.0, 0.2))
def test_peers_heard_lately_are_those_heard_within_the_quiet_time(updates: list[tuple[int, float]], alive: set[int],
                                                                  period_s: float) -> None:
    """heard_lately reads only the newest part of `heard` (kept in the order of its times, as the node keeps it):
    the same peers as checking every live peer's time."""
    heard: dict[int, float] = {}
    now = 0.0
    for a, dt in updates:  # (times only grow: the node's steps come in wall-time order)
        now += dt
        heard.pop(a, None)
        heard[a] = now
    for a in alive:
        heard.setdefault(a, now)  # (every live peer has a time: its token's if nothing else)
    now += 0.5
    quiet = max(TIMING.realtime_peer_silent_s, 3.0 * period_s)
    expected = {a for a in alive if now - heard[a] <= quiet}
    assert Neighbourhood.heard_lately(alive, heard, now, period_s, TIMING.realtime_peer_silent_s) == expected


def test_the_intruders_of_a_tick_are_the_peers_within_reach_it_did_not_wait_for() -> None:
    nb = Neighbourhood(S, A)
    nb.own[4] = nb.own[5] = (0.0, 0.0)
    assert nb.wait_set(5, ALIVE, {B: beacon(B, 4, 10.0, 0.0)}, {}) == {B}  # (C had no beacon of 4: not waited)
    fresh = {B: beacon(B, 5, 10.0, 0.0), C: beacon(C, 5, G.reach_m - 1.0, 0.0)}
    assert nb.intruders(5, fresh) == [fresh[C]]
    assert nb.intruders(5, {C: beacon(C, 5, G.reach_m + 1.0, 0.0)}) == []  # (out of reach: no matter)
    assert nb.intruders(6, fresh) == []  # (no wait set for 6 yet: nobody is an intruder)
    assert [b for b in fresh.values() if nb.intruder(5, b)] == nb.intruders(5, fresh)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 4 * G.step_m), st.floats(0, 2 * math.pi)), min_size=1, max_size=120))
def test_the_cells_around_a_moving_agent_are_listen_cells_at_every_step(moves):
    """`_around` keeps its cells while the agent stays within their margin: at every tick of a walk they are
    exactly the cells CellGrid.listen_cells names where the agent is."""
    nb = Neighbourhood(S, A)
    x, y = 100.0, 0.0
    for k, (d, a) in enumerate(moves):
        x, y = x + d * math.cos(a), y + d * math.sin(a)
        nb.on_state(k, (x, y))
        nb.after_command(k)
        assert nb.listen == G.listen_cells(x, y)
