"""The agent node's waits (agent/node.py, lockstep) on their own clocks: the wait for a lost clock counts from
when the tick's state came (not from 0), the wait for peers gives up after agent_wait_timeout_s even while a
peer keeps talking (its beacon for the tick never comes), and a stuck tick's beacon goes out again after
beacon_again_s, then 2, 4, 8 x that (never at every step). While the world stalls (its token gone, or nothing from
it for world_quiet_s though it publishes a tick it waits on again every republish_s) no wait is given up, and
every wait starts afresh when it speaks again."""

from __future__ import annotations

import dataclasses

from reconswarm.net.timing import Timing
from tests.support import left, world_token
from tests.unit.solo import SoloNode
from tests.unit.test_agent_node import A, B, C, S, T, beacon, beacons, clock, cmds, joined, started, state


def test_the_wait_for_a_lost_clock_counts_from_the_states_arrival() -> None:
    t0 = 50.0  # well into the run's wall time
    node = SoloNode(S, A, t0, T)
    node.step([joined(A)], t0)
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], t0)
    assert node.k == 0
    node.step([state(1, 100.1, 0.0)], t0 + 0.1)  # clock 1 lost
    assert not cmds(node.step([], t0 + 0.1 + 0.5 * T.agent_wait_timeout_s))
    assert [c.k for c in cmds(node.step([], t0 + 0.1 + T.agent_wait_timeout_s + 0.01))] == [1]


def test_the_wait_for_a_talking_peer_gives_up_after_the_wait_timeout() -> None:
    node = SoloNode(S, A, 0.0, T)
    node.step([joined(A), joined(B)], 0.0)
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0)], 0.0)
    assert node.k == 0
    node.step([clock(1, (A, B)), state(1, 100.1, 0.0)], 0.1)  # B's beacon for tick 1 never comes ...
    now = 0.1
    while now < 0.1 + T.agent_wait_timeout_s - 0.3:  # ... though B keeps talking (its tick-0 beacon again)
        now += 0.25
        assert not cmds(node.step([beacon(B, 0, 110.0, 0.0)], now)), now
    out = node.step([beacon(B, 0, 110.0, 0.0)], 0.1 + T.agent_wait_timeout_s + 0.01)
    assert [c.k for c in cmds(out)] == [1] and node.guessed_k == 1


def test_a_stuck_ticks_beacon_backs_off_doubling() -> None:
    patient = dataclasses.replace(T, agent_wait_timeout_s=1e3, peer_silent_s=1e3)  # stuck for good
    node = SoloNode(S, A, 0.0, patient)
    node.step([joined(A), joined(B)], 0.0)
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0)], 1.0)  # our beacon for tick 0 goes out at 1.0
    again = T.beacon_again_s
    sent_at = []
    now = 1.0
    while now < 1.0 + 20 * again:
        now = round(now + 0.01, 2)
        if beacons(node.step([], now)):
            sent_at.append(now)
    # again at 1.0 + 0.5 s, then 1 s, 2 s, 4 s after each (a step every 10 ms: 10 ms late at most)
    want, t = [], 1.0
    for n in range(4):
        t = t + again * 2**n + 0.01
        want.append(round(t, 2))
    assert sent_at[:4] == want
    assert node.k == -1  # (still waiting for B: no command)


W = Timing()  # (T takes the world to speak throughout: these tests are about its silence)


def frozen_mid_tick() -> SoloNode:
    """A and B acted on tick 0; the world published tick 1's clock and A's state, then froze (SIGSTOP) before
    B's state: B has nothing to announce until the world is back."""
    node = SoloNode(S, A, 0.0, W)
    node.step([joined(A), joined(B)], 0.0)
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0)], 0.0)
    assert node.k == 0
    node.step([clock(1, (A, B)), state(1, 100.1, 0.0)], 0.1)
    return node


def test_a_world_frozen_mid_tick_past_its_lease_is_waited_out_not_guessed_through() -> None:
    node = frozen_mid_tick()
    for now in (1.0, 2.0, 3.2, 5.0, 9.9):  # past agent_wait_timeout_s and peer_silent_s: nothing given up
        if now == 2.0:
            assert not cmds(node.step([world_token(False)], now))  # the world's lease ended
        assert not cmds(node.step([], now)), now
    # Back (10 s frozen): its token, then the rest of tick 1 and tick 1 again; every wait starts afresh.
    assert not cmds(node.step([world_token(True), clock(1, (A, B)), state(1, 100.1, 0.0)], 10.1))
    assert not cmds(node.step([], 10.1 + min(W.agent_wait_timeout_s, W.peer_silent_s) - 0.1))
    out = node.step([beacon(B, 1, 110.1, 0.0)], 13.0)  # B got its state and announced it
    assert [c.k for c in cmds(out)] == [1] and node.guessed_k == -1  # deterministic


def test_a_world_silent_for_world_quiet_s_is_a_stall_though_its_token_stays() -> None:
    """Frozen shorter than its lease (or its token's end not yet with us): the world's silence alone says it
    stalls. Once it speaks again and keeps publishing the tick, a peer still silent is given up, from its return."""
    node = frozen_mid_tick()
    assert W.world_quiet_s < W.agent_wait_timeout_s and W.world_quiet_s < W.peer_silent_s
    for now in (1.0, 3.2):
        assert not cmds(node.step([], now)), now
    now = 4.0  # back: tick 1 again, then every republish_s; B still silent
    assert not cmds(node.step([clock(1, (A, B)), state(1, 100.1, 0.0)], now))
    while now + W.republish_s < 4.0 + min(W.agent_wait_timeout_s, W.peer_silent_s):
        now = round(now + W.republish_s, 2)
        assert not cmds(node.step([clock(1, (A, B)), state(1, 100.1, 0.0)], now)), now
    out = node.step([clock(1, (A, B)), state(1, 100.1, 0.0)], 4.0 + W.agent_wait_timeout_s + 0.05)
    assert [c.k for c in cmds(out)] == [1] and node.guessed_k == 1  # a silent peer of a speaking world: a guess


def test_a_lost_clock_is_not_given_up_while_the_world_is_silent() -> None:
    node = SoloNode(S, A, 0.0, W)
    node.step([joined(A)], 0.0)
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    node.step([state(1, 100.1, 0.0)], 0.1)  # clock 1 lost, then the world froze
    assert not cmds(node.step([], 0.1 + W.agent_wait_timeout_s + 0.5))
    now = 0.1 + W.agent_wait_timeout_s + 1.0
    node.step([state(1, 100.1, 0.0)], now)  # back: our state again (its clock lost again)
    assert not cmds(node.step([], now + W.republish_s))
    for i in range(2, 8):
        out = node.step([state(1, 100.1, 0.0)], now + i * W.republish_s)
    assert [c.k for c in cmds(out)] == [1] and node.guessed_k == 1


def test_a_peer_whose_token_goes_while_we_wait_is_waited_for_no_more() -> None:
    """The wait set of a tick is kept between steps (`_expected`) until the clock or a token changes: C's token
    going while we wait for its beacon ends the wait once it has not come back within `token_confirm_s` (its
    robot: a lost one, where last seen)."""
    node = started()
    assert cmds(node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 105.0, 0.0), beacon(C, 0, 109.0, 0.0)],
                          0.0))
    assert not cmds(node.step([clock(1), state(1, 100.05, 0.0), beacon(B, 1, 105.0, 0.0)], 0.1))
    assert node.awaiting(0.1) == 1 and not cmds(node.step([], 0.15))  # C's beacon
    assert not cmds(node.step([left(C)], 0.2))
    assert [c.k for c in cmds(node.step([], 0.2 + T.token_confirm_s))] == [1]


def test_a_tick_whose_clock_comes_again_without_a_peer_is_waited_for_by_the_new_clock() -> None:
    """The world publishes a tick's clock again (its list of agents may have changed: C's process died and the
    world no longer counts it): the wait follows the newest clock of the tick, not the first."""
    node = started()
    node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 105.0, 0.0), beacon(C, 0, 109.0, 0.0)], 0.0)
    assert not cmds(node.step([clock(1), state(1, 100.05, 0.0), beacon(B, 1, 105.0, 0.0)], 0.1))
    assert [c.k for c in cmds(node.step([clock(1, (A, B))], 0.2))] == [1]


def test_awaiting_is_kept_until_the_next_step_or_for_agent_poll_s() -> None:
    """What `awaiting` said is kept (the runtime asks every node at every wake-up): a step forgets it at once
    (B's beacon in: one fewer), and without one it is asked anew after agent_poll_s (C silent by then: not
    counted). In between, the count stays what it was."""
    t0 = 100.0
    node = SoloNode(S, A, t0, T)
    node.step([joined(A), joined(B), joined(C)], t0)
    node.step([state(0, 100.0, 0.0)], t0)
    assert node.awaiting(t0) == 3  # B's beacon, C's beacon and the clock
    node.step([beacon(B, 0, 105.0, 0.0)], t0 + 0.01)
    assert node.awaiting(t0 + 0.01) == 2  # the step forgot what it said
    silent = t0 + T.peer_silent_s  # C silent from then (heard by its token at t0); B heard at t0 + 0.01
    assert node.awaiting(silent - 0.02) == 2
    assert node.awaiting(silent + 0.02) == 2  # asked again within agent_poll_s: kept, though C fell silent
    assert node.awaiting(silent - 0.02 + T.agent_poll_s + 0.001) == 1  # after it: anew (only the clock)
