"""The agent node's state machine (agent/node.py) case by case, from its mutation survivors: how many messages
`awaiting` tells the runtime to sleep for, which tick a step is about, who is planned with as a live peer and who
as a lost robot (a robot whose agent is gone blocks a passage with the hull beside it; a live peer does not),
when a peer's silence starts, the joining rule (every cached set) only for a first tick mid-mission, the exact
revisions lockstep merges, realtime's windows, and what goes out when (the obstacle set again after a new
session or in a new home cell, the cells after a command, a single beacon per tick)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agent.brain import AgentBrain, Peer
from agent.messages import Output
from agent.neighbours import Cells
from agent.node import AgentNode
from reconswarm.net import wire
from reconswarm.scenario.model import PlannerKind
from tests.support import joined, left, world_token
from tests.unit.test_agent_node import DT, RADIUS, A, B, C, S, T, beacon, beacons, clock, cmds, started, state

D, E = 4, 5  # two more peers of the scenario, far away at their starts
HULL = ((110.0, 0.0, "diamond"), (111.0, 1.0, "diamond"), (111.0, -1.0, "diamond"))  # 10 m ahead of us
HULL_XY = {"diamond": np.array([[110.0, 0.0], [111.0, 1.0], [111.0, -1.0]])}
PATIENT = dataclasses.replace(T, agent_wait_timeout_s=10.0)  # longer than peer_silent_s: silence decides
RT = {"mode": "realtime", "speed": 10.0}
Hulls = dict[str, tuple[tuple[float, float], ...]]


def sets(out: list[Output]) -> list[wire.ObstacleSet]:
    return [o for o in out if isinstance(o, wire.ObstacleSet)]


def vw(out: list[Output]) -> list[tuple[int, float, float]]:
    return [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)]


class Ref:
    """The brain the node must drive, stepped by hand with the inputs the protocol says each tick uses."""

    def __init__(self) -> None:
        self.brain = AgentBrain(S, A)

    def tick(self, k: int, p: tuple[float, float], peers: list[Peer], lost: list[Peer] | None = None,
             scan: dict[str, np.ndarray] | None = None, shared: list[dict[str, np.ndarray]] | None = None
             ) -> tuple[int, float, float]:
        u, _ = self.brain.tick(k, np.array(p), scan or {}, peers, shared or [], None, lost or [])
        return (k, *self.brain.inputs(u, 0.0))


def peer(a: int, x: float, y: float = 0.0) -> Peer:
    return Peer(a, x, y, RADIUS[a])


# ------------------------------------------------------------------------------------------ awaiting

def test_awaiting_is_about_the_next_tick_not_the_newest_state() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0)], 0.0)
    assert node.k == 0 and node.awaiting(0.0) is None  # tick 0 is done: only a new state can move us on
    # Tick 2's state was lost; tick 3's is in with its clock and B's beacon; tick 1 lacks its clock and B's beacon.
    out = node.step([state(1, 100.0, 0.0), state(3, 100.0, 0.0), clock(3, (A, B)), beacon(B, 3, 110.0, 0.0)], 0.1)
    assert not cmds(out) and node.k == 0  # tick 1 first (lockstep never skips a tick it has the state of)
    assert node.awaiting(0.1) == 2  # tick 1: B's beacon and the clock
    out = node.step([clock(1, (A, B)), beacon(B, 1, 110.0, 0.0)], 0.2)
    assert [c.k for c in cmds(out)] == [1, 3]  # then tick 3 (its data is in; B's beacon of tick 2 never came)


def test_awaiting_in_realtime_is_about_the_newest_state() -> None:
    node = started(peers=(B, C))
    node.step([clock(0, (A, B, C), **RT), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0), beacon(C, 0, 120.0, 0.0)],
              0.0)
    assert node.k == 0
    out = node.step([state(1, 100.0, 0.0), beacon(B, 1, 110.0, 0.0), beacon(C, 1, 120.0, 0.0), state(2, 100.0, 0.0)],
                    0.001)
    assert not cmds(out) and [b.k for b in beacons(out)] == [2]  # tick 1 is stale; tick 2 waits for both beacons
    assert node.awaiting(0.001) == 2  # (no clock of tick 2 is waited for in realtime)
    assert node.guessed_k == -1  # realtime never says a guess (it is not lockstep)


def test_awaiting_counts_peers_the_clock_names_before_their_tokens_and_a_missing_clock() -> None:
    node = started(peers=())
    node.step([clock(0, (A, B, C)), state(0, 100.0, 0.0)], 0.0)
    assert node.awaiting(0.0) == 2  # B and C are counted by the world's clock; their tokens are on their way
    t0 = 100.0  # well into the run's wall time: a peer's silence is counted from its token
    node = AgentNode(S, A, t0, T)
    node.step([joined(A), joined(B)], t0)
    node.step([state(0, 100.0, 0.0)], t0)
    assert node.awaiting(t0 + 0.5) == 2  # B's beacon and the clock
    assert node.awaiting(t0 + T.peer_silent_s + 0.5) == 1  # B silent since its token: only the clock


def test_awaiting_counts_beacons_of_peers_heard_the_tick_before_but_not_waited_for() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 160.0, 0.0)], 0.0)  # B in a cell we hear,
    assert node.k == 0                                                                    # but too far to matter
    node.step([state(1, 100.0, 0.0)], 0.1)
    assert node.awaiting(0.1) == 2  # B's beacon of tick 1 will come (not waited for, but the runtime sleeps on it)
    node.step([clock(1, (A, B))], 0.1)
    assert node.k == 1  # not waited for


def test_awaiting_counts_the_linked_peers_sets_not_yet_in() -> None:
    pos = {A: 100.0, B: 110.0, C: 120.0, D: 105.0, E: 115.0}  # all within link range
    s = dataclasses.replace(S, agents=tuple(
        dataclasses.replace(a, start_m=(pos[a.id] - 0.5, 0.0)) if a.id in pos else a for a in S.agents))
    node = AgentNode(s, A, 0.0, T)
    node.step([joined(a) for a in (A, B, C, D, E)], 0.0)
    far: Hulls = {"hexagon": ((600.0, 0.0), (601.0, 1.0), (601.0, -1.0))}
    out = node.step([wire.ObstacleSet(D, 0, 3, far), clock(0, (A, B, C, D, E)), state(0, 100.0, 0.0),
                     beacon(B, 0, 110.0, 0.0, rev=1), beacon(C, 0, 120.0, 0.0, rev=2),
                     wire.Beacon(D, 0, 0.0, 105.0, 0.0, RADIUS[D], 3),
                     wire.Beacon(E, 0, 0.0, 115.0, 0.0, RADIUS[E], 0)], 0.0)
    assert not cmds(out)
    assert node.awaiting(0.0) == 2  # B's and C's sets; D's is in, E has none
    node.step([wire.ObstacleSet(B, 0, 1, far), wire.ObstacleSet(C, 0, 2, far)], 0.01)
    assert node.k == 0 and node.guessed_k == -1


def test_awaiting_adds_the_linked_sets_to_the_beacons_also_heard() -> None:
    node = started(peers=(B, D))  # D starts far away: not waited for at tick 0
    node.step([clock(0, (A, B, D)), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0),
               wire.Beacon(D, 0, 0.0, 160.0, 0.0, RADIUS[D], 0)], 0.0)
    assert node.k == 0
    node.step([clock(1, (A, B, D)), state(1, 100.0, 0.0), beacon(B, 1, 110.0, 0.0, rev=1)], 0.05)
    assert node.k == 0 and node.awaiting(0.05) == 2  # B's set, and D's beacon of tick 1 (heard, not waited for)


def test_awaiting_for_a_late_joiner_is_a_count() -> None:
    node = started(peers=(B, C))
    node.step([clock(300, (A, B, C)), state(300, 100.0, 0.0), beacon(B, 300, 900.0, 0.0, rev=4),
               beacon(C, 300, 120.0, 0.0)], 0.0)
    assert node.k == -1 and node.awaiting(0.0) == 1  # (B's cached set; its beacon is in)


# ------------------------------------------------------------------------------------- live or lost

def test_a_robot_whose_agent_is_gone_is_lost_and_blocks_the_passage_beside_a_hull() -> None:
    node, ref = started(peers=(B, C)), Ref()
    out = node.step([clock(0), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL)), beacon(B, 0, 140.0, 0.0),
                     beacon(C, 0, 107.0, 0.0)], 0.0)
    assert vw(out) == [ref.tick(0, (100.0, 0.0), [peer(B, 140.0), peer(C, 107.0)], scan=HULL_XY)]
    # C's agent dies (a forged token keeps it alive by its membership); the world's clock of tick 1 lacks it.
    out = node.step([clock(1, (A, B)), state(1, 100.05, 0.0), beacon(B, 1, 140.0, 0.0)], 0.05)
    live = Ref()
    live.tick(0, (100.0, 0.0), [peer(B, 140.0), peer(C, 107.0)], scan=HULL_XY)
    assert vw(out) == [ref.tick(1, (100.05, 0.0), [peer(B, 140.0)], lost=[peer(C, 107.0)])]
    assert vw(out) != [live.tick(1, (100.05, 0.0), [peer(B, 140.0), peer(C, 107.0)])]  # (lost is not live)


def test_a_tick_judges_lost_peers_by_its_own_clock_not_a_newer_one() -> None:
    """The world held C's robot at tick 1 (its clock of 1 lacks C; a forged token keeps C alive by its
    membership), and counts C again at tick 2 (restarted): tick 1 still plans C as a lost robot."""
    node, ref = started(peers=(B, C)), Ref()
    node.step([clock(0), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL)), beacon(B, 0, 140.0, 0.0),
               beacon(C, 0, 107.0, 0.0)], 0.0)
    ref.tick(0, (100.0, 0.0), [peer(B, 140.0), peer(C, 107.0)], scan=HULL_XY)
    out = node.step([clock(1, (A, B)), clock(2, (A, B, C)), state(1, 100.05, 0.0), beacon(B, 1, 140.0, 0.0)], 0.05)
    assert vw(out) == [ref.tick(1, (100.05, 0.0), [peer(B, 140.0)], lost=[peer(C, 107.0)])]


def test_a_waited_peer_given_up_is_planned_live_where_last_heard() -> None:
    node, ref = started(peers=(B,)), Ref()
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL)), beacon(B, 0, 107.0, 0.0)],
              0.0)
    ref.tick(0, (100.0, 0.0), [peer(B, 107.0)], scan=HULL_XY)
    node.step([clock(1, (A, B)), state(1, 100.05, 0.0)], 0.1)
    out = node.step([], T.peer_silent_s + 0.1)  # B silent: a guess, with B's latest beacon as a live peer
    assert node.guessed_k == 1
    lost = Ref()
    lost.tick(0, (100.0, 0.0), [peer(B, 107.0)], scan=HULL_XY)
    assert vw(out) == [ref.tick(1, (100.05, 0.0), [peer(B, 107.0)])]
    assert vw(out) != [lost.tick(1, (100.05, 0.0), [], lost=[peer(B, 107.0)])]


def test_a_tick_plans_with_the_peers_beacon_of_that_tick_not_a_newer_one() -> None:
    node = started()
    out = node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0), beacon(B, 1, 104.0, 0.0),
                     beacon(C, 0, 120.0, 0.0)], 0.0)
    want = Ref().tick(0, (100.0, 0.0), [peer(B, 110.0), peer(C, 120.0)])
    assert vw(out) == [want] and want != Ref().tick(0, (100.0, 0.0), [peer(B, 104.0), peer(C, 120.0)])


def test_realtime_a_peer_the_newest_clock_counts_gone_is_lost_though_its_token_stays() -> None:
    node, ref = started(peers=(B, C)), Ref()
    node.step([clock(0, (A, B, C), **RT), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0), beacon(C, 0, 104.0, 0.0)],
              0.0)
    ref.tick(0, (100.0, 0.0), [peer(B, 110.0), peer(C, 104.0)])
    node.step([clock(1, (A, B), **RT)], 0.5)  # C's agent died (its token is forged); tick 2 comes without a clock
    out = node.step([state(2, 100.0, 0.0), beacon(B, 2, 110.0, 0.0)], 1.5)
    assert vw(out) == [ref.tick(2, (100.0, 0.0), [peer(B, 110.0)], lost=[peer(C, 104.0)])]


def test_realtime_a_peer_whose_token_went_is_not_waited_for() -> None:
    node = started(peers=(B, C))
    node.step([clock(0, (A, B, C), **RT), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0), beacon(C, 0, 120.0, 0.0)],
              0.0)
    node.step([left(C)], 0.001)
    out = node.step([state(1, 100.0, 0.0), beacon(B, 1, 110.0, 0.0)], 0.002)
    assert [c.k for c in cmds(out)] == [1]  # at once, not at the deadline


def test_realtime_a_neighbour_many_ticks_behind_survives_pruning() -> None:
    """Realtime judges a peer by wall time (heard lately), not by how many ticks old its beacon is."""
    node = started(peers=(B,))
    node.step([clock(0, (A, B), **RT), state(0, 100.0, 0.0), beacon(B, 0, 104.0, 0.0)], 0.0)
    node.step([clock(80, (A, B), **RT), state(80, 100.0, 0.0)], 0.05)
    node.step([], node.wake_at_s() or 0.1)
    assert node.k == 80  # (a prune tick; B's beacon is 80 ticks old, heard 0.05 s ago)
    out = node.step([clock(81, (A, B), **RT), state(81, 100.0, 0.0)], 0.15)
    out += node.step([], node.wake_at_s() or 0.2)
    brain = AgentBrain(S, A)
    for k in (0, 80):
        brain.tick(k, np.array((100.0, 0.0)), {}, [peer(B, 104.0)], [])
    u, _ = brain.tick(81, np.array((100.0, 0.0)), {}, [peer(B, 104.0)], [])
    assert vw(out) == [(81, *brain.inputs(u, 0.0))]


# ------------------------------------------------------------------------------- silence and membership

def test_a_peer_is_silent_counting_from_its_token_or_from_the_clock_that_named_it() -> None:
    node = started(peers=(B,), timing=PATIENT)  # B's token at 0.0; C named by the clock at 1.0; neither talks
    node.step([clock(0, (A, B, C)), state(0, 100.0, 0.0)], 1.0)
    assert not cmds(node.step([], T.peer_silent_s + 0.5))  # C: silent for 2.5 s only
    assert [c.k for c in cmds(node.step([], 1.0 + T.peer_silent_s + 0.01))] == [0]
    assert node.guessed_k == 0


def test_a_peers_silence_counts_from_its_token_not_from_the_first_clock() -> None:
    node = started(peers=(B,), timing=PATIENT)  # B's token at 0.0
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0)], 2.0)
    assert [c.k for c in cmds(node.step([], T.peer_silent_s + 0.01))] == [0]


def test_a_peer_back_while_we_act_is_waited_for_where_it_was_held() -> None:
    node = started(peers=(B,))
    node.step([left(B)], 0.0)
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.01)
    assert node.k == 0
    node.step([joined(B)], 0.02)  # B's agent is back (restarted) while we are at tick 0
    out = node.step([clock(1, (A, B)), state(1, 100.05, 0.0)], 0.05)
    assert not cmds(out) and node.awaiting(0.05) == 1  # its robot was held at its start, near us: waited for
    out = node.step([beacon(B, 1, 110.0, 0.0)], 0.06)
    assert [c.k for c in cmds(out)] == [1] and node.guessed_k == -1


def test_a_peer_back_and_heard_again_is_placed_by_its_beacons_again() -> None:
    """Once a peer back is heard, only its beacon of the tick before says whether a tick waits for it: a peer
    that said nothing of tick 2 (stuck, re-sending its beacon of tick 1) is not waited for at tick 3."""
    node = started(peers=(B,))
    node.step([left(B)], 0.0)
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.01)
    node.step([joined(B)], 0.02)
    node.step([clock(1, (A, B)), state(1, 100.0, 0.0)], 0.05)
    node.step([beacon(B, 1, 110.0, 0.0)], 0.06)
    assert node.k == 1 and node.guessed_k == -1
    node.step([clock(2, (A, B)), state(2, 100.0, 0.0)], 0.1)
    now = 0.1
    while node.k < 2:  # B keeps re-sending its beacon of tick 1: tick 2 gives up after agent_wait_timeout_s
        now = round(now + 0.25, 2)
        node.step([beacon(B, 1, 110.0, 0.0)], now)
    assert now < 0.1 + T.agent_wait_timeout_s + 0.3 and node.guessed_k == 2
    out = node.step([clock(3, (A, B)), state(3, 100.0, 0.0), beacon(B, 1, 110.0, 0.0)], now + 0.05)
    assert [c.k for c in cmds(out)] == [3]  # at once: B announced nothing of tick 2


def test_a_peer_backs_first_beacon_before_our_state_is_no_intruder() -> None:
    """The same as test_a_peer_back_while_we_act_is_waited_for_where_it_was_held, with B's beacon of tick 1 in
    before our own state of tick 1 (an ordinary order: B's state came first). The wait set of tick 1 must not
    depend on that order (agent/neighbours.py: with no beacon of k-1 from a peer that joined again, the
    position it is held at counts): B is expected, so its beacon is no intruder and nothing was guessed."""
    node = started(peers=(B,))
    node.step([left(B)], 0.0)
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.01)
    node.step([joined(B)], 0.02)
    node.step([beacon(B, 1, 110.0, 0.0)], 0.04)
    out = node.step([clock(1, (A, B)), state(1, 100.05, 0.0)], 0.05)
    assert [c.k for c in cmds(out)] == [1]
    assert node.guessed_k == -1


def test_a_late_beacon_of_the_tick_just_acted_on_within_reach_is_a_guess_said_once() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    assert node.k == 0 and node.guessed_k == -1
    node.step([wire.Beacon(D, 0, 0.0, 101.0, 0.0, RADIUS[D], 0)], 0.01)  # D was far at its start: not waited for
    assert node.guessed_k == 0
    node.step([clock(1, (A,)), state(1, 100.0, 0.0)], 0.05)
    node.step([wire.Beacon(E, 1, DT, 101.0, 0.0, RADIUS[E], 0)], 0.06)  # another one, later: the first stays
    node.step([clock(2, (A,)), state(2, 100.0, 0.0), wire.Beacon(7, 2, 2 * DT, 101.0, 0.0, RADIUS[7], 0)], 0.1)
    assert node.k == 2 and node.guessed_k == 0  # (agent 7's beacon made tick 2 a guess too: still the first said)


def test_a_beacon_within_reach_from_a_peer_not_waited_for_makes_the_tick_a_guess() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    node.step([clock(1, (A,)), state(1, 100.0, 0.0), wire.Beacon(D, 1, DT, 101.0, 0.0, RADIUS[D], 0)], 0.05)
    assert node.k == 1 and node.guessed_k == 1  # (D said nothing at tick 0: it cannot be within reach at 1)


def test_the_worlds_scan_reports_other_robots_never_our_own() -> None:
    node = started(peers=(B, C))
    node.step([left(C)], 0.0)
    held = wire.Scan(A, 0, 0.0, (), ((A, 100.0, 0.0), (C, 104.0, 0.0)))
    out = node.step([clock(0, (A, B)), state(0, 100.0, 0.0, scan=held), beacon(B, 0, 110.0, 0.0)], 0.01)
    assert vw(out) == [Ref().tick(0, (100.0, 0.0), [peer(B, 110.0)], lost=[peer(C, 104.0)])]
    node.step([joined(C), beacon(C, 1, 104.0, 0.0)], 0.02)  # C's agent is back and talks: its beacon replaces it
    assert node.last_seen[C].k == 1 and node.last_seen[C].id == C
    node = started(peers=(B,))  # the world's clock does not count us (held): our own robot is still no obstacle
    held = wire.Scan(A, 0, 0.0, (), ((A, 100.0, 0.0),))
    out = node.step([clock(0, (B,)), state(0, 100.0, 0.0, scan=held), beacon(B, 0, 110.0, 0.0)], 0.01)
    assert vw(out) == [Ref().tick(0, (100.0, 0.0), [peer(B, 110.0)])]


# ------------------------------------------------------------------------------------ ticks and waits

def test_a_second_lost_clock_is_waited_for_from_its_own_state() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    node.step([state(1, 100.0, 0.0)], 0.1)  # clock 1 lost
    assert [c.k for c in cmds(node.step([], 0.1 + T.agent_wait_timeout_s + 0.01))] == [1]
    t2 = 0.2 + T.agent_wait_timeout_s
    node.step([state(2, 100.0, 0.0)], t2)  # clock 2 lost too
    assert not cmds(node.step([], t2 + 0.5 * T.agent_wait_timeout_s))
    assert [c.k for c in cmds(node.step([], t2 + T.agent_wait_timeout_s + 0.01))] == [2]


def test_the_joining_rule_holds_only_for_a_first_tick_mid_mission() -> None:
    """A first tick after 0 waits for every peer's cached set (any revision, far ones too) and merges them all;
    tick 0, and any tick after our first command, waits only for the sets of the peers within link range."""
    far: Hulls = {"hexagon": ((600.0, 0.0), (601.0, 1.0), (601.0, -1.0))}
    node = started(peers=(B,))  # tick 0: B is 50 m away (beyond link range), announcing a set we have
    node.step([wire.ObstacleSet(B, 0, 1, far), clock(0, (A, B)), state(0, 100.0, 0.0)], 0.0)
    node.step([beacon(B, 0, 150.0, 0.0, rev=1)], 0.01)
    assert node.k == 0 and "hexagon" not in node.brain.obstacle_sets()  # not linked: not merged
    node = started(peers=(B,))  # the same with B's set not in: not waited for, at tick 0 or after
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 150.0, 0.0, rev=2)], 0.0)
    assert node.k == 0
    node.step([clock(1, (A, B)), state(1, 100.0, 0.0), beacon(B, 1, 150.0, 0.0, rev=3)], 0.05)
    assert node.k == 1 and node.guessed_k == -1
    node = started(peers=(B,))  # first tick 1: joining
    node.step([clock(1, (A, B)), state(1, 100.0, 0.0), beacon(B, 1, 150.0, 0.0, rev=1)], 0.0)
    assert node.k == -1  # B's cached set first
    node.step([wire.ObstacleSet(B, 0, 1, far)], 0.01)
    assert node.k == 1 and "hexagon" in node.brain.obstacle_sets()


def test_a_restarted_peer_counting_its_revisions_again_is_not_waited_for() -> None:
    """A peer restarted counts its revisions from 1 again: a revision at or below the one we merged is static
    knowledge we hold (its new set need not come before we act)."""
    node = started(peers=(B,))
    hulls = {r: wire.ObstacleSet(B, r, r, {"diamond": ((130.0 + r, 0.0), (131.0, 1.0), (131.0, -1.0))}) for r in (1, 2)}
    for k in range(21):
        rev = 1 if k < 10 else 2
        batch: list = [clock(k, (A, B)), state(k, 100.0, 0.0), beacon(B, k, 105.0, 0.0, rev)]
        if k in (0, 10):
            batch.append(hulls[rev])
        node.step(batch, k * 0.01)
    assert node.k == 20 and list(node.sets[B]) == [2]
    node.step([clock(21, (A, B)), state(21, 100.0, 0.0), beacon(B, 21, 105.0, 0.0, 1)], 0.3)  # B restarted
    assert node.k == 21 and node.guessed_k == -1


def test_lockstep_merges_the_revision_the_beacon_announces_not_a_newer_one() -> None:
    near = {r: wire.ObstacleSet(B, 0, r, {f"o{r}": ((108.0 + 2 * r, 5.0), (109.0 + 2 * r, 6.0), (109.0 + 2 * r, 4.0))})
            for r in (1, 2)}
    node = started(peers=(B,))
    out = node.step([near[1], near[2], clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0, rev=1)], 0.0)
    ref = Ref()
    shared = [{"o1": np.array(near[1].obstacles["o1"])}]
    assert vw(out) == [ref.tick(0, (100.0, 0.0), [peer(B, 110.0)], shared=shared)]
    assert set(node.brain.obstacle_sets()) == {"o1"}


def test_a_wait_given_up_still_merges_the_linked_peers_sets() -> None:
    node = started(peers=(B, C))  # C never answers; B is linked and its set is in
    hull = wire.ObstacleSet(B, 0, 1, {"o": ((112.0, 5.0), (113.0, 6.0), (113.0, 4.0))})
    node.step([hull, clock(0), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0, rev=1)], 0.0)
    node.step([], T.agent_wait_timeout_s + 0.01)
    assert node.k == 0 and node.guessed_k == 0 and "o" in node.brain.obstacle_sets()


def test_each_tick_plans_with_every_scan_since_the_last_command() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    one = wire.Scan(A, 1, DT, ((130.0, 0.0, "one"), (131.0, 1.0, "one"), (131.0, -1.0, "one")))
    two = wire.Scan(A, 2, 2 * DT, ((130.0, 20.0, "two"), (131.0, 21.0, "two"), (131.0, 19.0, "two")))
    node.step([clock(1, (A,)), state(1, 100.0, 0.0, scan=one)], 0.05)
    assert node.k == 1 and set(node.brain.obstacle_sets()) == {"one"}  # lockstep: tick 1's own scan
    node.step([clock(3, (A,), **RT), state(2, 100.0, 0.0, scan=two), state(3, 100.0, 0.0)], 0.1)
    node.step([], node.wake_at_s() or 0.2)
    assert node.k == 3 and set(node.brain.obstacle_sets()) == {"one", "two"}  # realtime skipped tick 2: its scan too


def test_realtime_merges_the_newest_set_of_a_linked_peer_even_when_it_comes_late() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B), **RT), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0, rev=1)], 0.0)
    assert node.k == 0 and node.brain.obstacle_sets() == {}  # B's set has not come yet
    node.step([wire.ObstacleSet(B, 0, 1, {"o": ((112.0, 5.0), (113.0, 6.0), (113.0, 4.0))})], 0.001)
    node.step([clock(1, (A, B), **RT), state(1, 100.0, 0.0), beacon(B, 1, 110.0, 0.0, rev=1)], 0.005)
    assert node.k == 1 and set(node.brain.obstacle_sets()) == {"o"}


# ------------------------------------------------------------------------------------------- outputs

def test_nothing_goes_out_before_the_mission_and_no_timer_is_set() -> None:
    node = AgentNode(S, A, 0.0, T)
    assert node.wake_at_s() is None
    assert node.step([joined(A)], 0.0) == []  # (no obstacle set of revision 0)
    node.step([world_token(False)], 0.5)
    assert node.step([world_token(True)], 1.0) == []  # a world stalled before the start: nothing to do


def test_a_new_session_publishes_the_set_once_at_the_last_commanded_tick() -> None:
    node = started(peers=())
    out = node.step([clock(0, (A,)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL))], 0.0)
    grown = sets(out)
    assert [(s.id, s.k, s.rev) for s in grown] == [(A, 0, 1)]  # knowledge grew at tick 0
    assert [c.id for c in cmds(out)] == [A]
    assert isinstance(out[-1], Cells) and out[-1].listen is not None  # after the command: only our cells
    node.reconnected(1.0)
    out = node.step([], 1.1)
    assert [(s.id, s.k, s.rev, set(s.obstacles)) for s in sets(out)] == [(A, 0, 1, {"diamond"})]
    assert sets(node.step([], 1.2)) == []  # once


def test_a_new_home_cell_gets_the_set_again_a_new_listening_cell_does_not() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL))], 0.0)
    out = node.step([clock(1, (A,)), state(1, 112.0, 0.0)], 0.05)  # a new home cell: its cache lacks our set
    assert [type(o) for o in out][:3] == [Cells, wire.ObstacleSet, wire.Beacon]
    assert [(s.id, s.k, s.rev) for s in sets(out)] == [(A, 0, 1)]  # (as of our last command)
    home = node.nb.grid.cell_of(112.0, 0.0)
    out = node.step([clock(2, (A,)), state(2, 120.0, 20.0)], 0.1)  # same home cell, more cells to listen to
    assert isinstance(out[0], Cells) and out[0].home == home
    assert [type(o) for o in out][:3] == [Cells, wire.Beacon, wire.Cmd] and sets(out) == []
    node = started(peers=())  # knowing nothing: no set to put
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    out = node.step([clock(1, (A,)), state(1, 112.0, 0.0)], 0.05)
    assert sets(out) == [] and isinstance(out[0], Cells)


def test_a_stuck_ticks_set_goes_again_as_of_that_tick() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL)), beacon(B, 0, 140.0, 0.0)],
              0.0)
    node.step([clock(1, (A, B)), state(1, 100.0, 0.0)], 1.0)
    out = node.step([], 1.0 + T.beacon_again_s + 0.01)
    assert [(s.id, s.k, s.rev) for s in sets(out)] == [(A, 1, 1)]


def test_realtime_one_beacon_and_one_command_per_tick() -> None:
    node = started(peers=(B,))
    out = node.step([clock(0, (A, B), **RT), state(0, 100.0, 0.0)], 0.0)
    assert [b.k for b in beacons(out)] == [0] and not cmds(out)
    assert node.step([], 0.001) == []  # still waiting for B: no second beacon
    out = node.step([beacon(B, 0, 110.0, 0.0)], 0.002)
    assert [c.k for c in cmds(out)] == [0]
    assert node.step([beacon(B, 0, 110.0, 0.0)], 0.003) == []  # tick 0 is done: no second command
    out = node.step([state(1, 100.0, 0.0), beacon(B, 1, 110.0, 0.0)], 0.004)
    assert [c.k for c in cmds(out)] == [1] and node.guessed_k == -1  # (realtime says no guess: not lockstep)


def test_realtime_acts_a_fraction_of_a_period_after_the_state() -> None:
    node = started(peers=(B,))
    out = node.step([clock(0, (A, B), mode="realtime", speed=1.0), state(0, 100.0, 0.0)], 0.5)  # B heard lately
    assert not cmds(out) and node.wake_at_s() == pytest.approx(0.5 + T.realtime_act_fraction * DT)
    node = started(peers=(B,))  # speed 0: as fast as it can, so at once on whatever it has
    out = node.step([clock(0, (A, B), mode="realtime", speed=0.0), state(0, 100.0, 0.0)], 0.5)
    assert [c.k for c in cmds(out)] == [0] and node.wake_at_s() is None


def test_the_waiting_log_runs_before_any_state() -> None:
    node = started(peers=())
    assert "no state yet" in node.waiting_for()
    node.step([clock(0, (A,))], 0.0)
    assert node.step([], T.waiting_log_s + 0.1) == []  # (logs what it lacks; no state to name yet)
    assert "no state yet" in node.waiting_for()


def test_realtime_after_the_first_command_plans_with_the_scans_of_skipped_ticks() -> None:
    node = started(peers=())
    node.step([clock(0, (A,), **RT), state(0, 100.0, 0.0)], 0.0)
    assert node.k == 0
    one = wire.Scan(A, 1, DT, ((130.0, 0.0, "one"), (131.0, 1.0, "one"), (131.0, -1.0, "one")))
    node.step([clock(2, (A,), **RT), state(1, 100.0, 0.0, scan=one), state(2, 100.0, 0.0)], 0.01)
    node.step([], node.wake_at_s() or 0.1)
    assert node.k == 2 and set(node.brain.obstacle_sets()) == {"one"}  # tick 1 skipped, its scan not


@pytest.mark.parametrize("mode", ["lockstep", "realtime"])
def test_the_virtual_leader_merges_every_peers_set_into_the_union(mode: str) -> None:
    s = dataclasses.replace(S, planner=dataclasses.replace(S.planner, kind=PlannerKind.VIRTUAL_LEADER))
    node = AgentNode(s, A, 0.0, T)
    node.step([joined(A), joined(B)], 0.0)
    kw = RT if mode == "realtime" else {}
    far = wire.ObstacleSet(B, 0, 1, {"hexagon": ((600.0, 0.0), (601.0, 1.0), (601.0, -1.0))})
    node.step([far, clock(0, (A, B), **kw), state(0, 100.0, 0.0), beacon(B, 0, 900.0, 0.0, rev=1)], 0.0)
    node.step([], node.wake_at_s() or 0.01)
    assert node.k == 0
    assert "hexagon" in dict(node.brain.union.sorted_items())  # far beyond link range: the union has it
    assert "hexagon" not in node.brain.obstacle_sets()  # (our own knowledge merges linked peers' sets only)


def test_with_the_deadlock_perturbation_on_the_brain_is_fed_each_tick() -> None:
    """perturbation_mps > 0: the stall detector keeps a window of ticks (stall_window_s = 5 s, 100 ticks) and
    perturbs a robot that made no progress over it. Standing still for 120 ticks, the node commands every tick
    as the brain fed that tick does, and the perturbation comes in (the command changes with no new input)."""
    s = dataclasses.replace(S, planner=dataclasses.replace(S.planner, perturbation_mps=0.5))
    node = started(node_s=s, peers=())
    ref = AgentBrain(s, A)
    got, want = [], []
    for k in range(120):
        got += vw(node.step([clock(k, (A,)), state(k, 100.0, 0.0)], k * 0.01))
        u, _ = ref.tick(k, np.array([100.0, 0.0]), {}, [], [])
        want.append((k, *ref.inputs(u, 0.0)))
    assert got == want and got[-1][1:] != got[0][1:]
