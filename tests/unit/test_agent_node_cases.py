"""The agent node's state machine (agent/node.py) case by case, from its mutation survivors: how many messages
`awaiting` tells the runtime to sleep for, which tick a step is about, who is planned with as a live peer and who
as a lost robot (a robot whose agent is gone blocks a passage with the hull beside it; a live peer does not),
when a peer's silence starts, a peer back in the mission, late beacons as guesses. Ticks, waits and what goes out
when: tests/unit/test_agent_node_outputs.py."""

from __future__ import annotations

import dataclasses

import numpy as np

from agent.brain import AgentBrain, Peer
from agent.messages import Output
from reconswarm.net.wire import wire
from tests.support import joined, left
from tests.unit.solo import SoloNode
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
    node = SoloNode(S, A, t0, T)
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
    node = SoloNode(s, A, 0.0, T)
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


def test_realtime_a_silent_peer_the_scan_says_is_held_near_us_is_planned_with_where_it_stands() -> None:
    """B's agent is alive (its token, the clock) but said nothing for longer than realtime's silence (its
    process stalled): not a peer heard lately, yet the world's scan says its robot stands held beside us. The
    tick plans with it there (planning without it drove a robot through it at --speed 10 under a flood)."""
    node, ref = started(peers=(B,)), Ref()
    out = node.step([clock(0, (A, B), **RT), state(0, 100.0, 0.0), beacon(B, 0, 140.0, 0.0)], 0.0)
    assert vw(out) == [ref.tick(0, (100.0, 0.0), [peer(B, 140.0)])]
    held = wire.Scan(A, 40, 40 * DT, (), ((B, 106.0, 0.0),))
    out = node.step([clock(40, (A, B), **RT), state(40, 100.0, 0.0, scan=held)], 2.0)  # B silent for 2 s
    out += node.step([], node.wake_at_s() or 2.1)
    assert vw(out) == [ref.tick(40, (100.0, 0.0), [peer(B, 106.0)])]


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
    assert node.h.last_seen[C].k == 1 and node.h.last_seen[C].id == C
    node = started(peers=(B,))  # the world's clock does not count us (held): our own robot is still no obstacle
    held = wire.Scan(A, 0, 0.0, (), ((A, 100.0, 0.0),))
    out = node.step([clock(0, (B,)), state(0, 100.0, 0.0, scan=held), beacon(B, 0, 110.0, 0.0)], 0.01)
    assert vw(out) == [Ref().tick(0, (100.0, 0.0), [peer(B, 110.0)])]
