"""Our session losing its router (or finding a different one) mid-mission in lockstep: whatever was in flight to
us meanwhile is lost, and nothing tells which of it a tick needed (a peer's beacon from outside our wait set is
re-sent by nobody): the next tick we act on is a guess, said in our reports (`guessed_k`), so the summary says
`deterministic: false` from then. Before the mission's first clock, and in realtime, a link change says nothing."""

from __future__ import annotations

from agent.brain import Peer
from reconswarm.net.node import RouterReach
from tests.support import joined, left, world_token
from tests.unit.solo import SoloNode
from tests.unit.test_agent_node import RADIUS, A, B, C, T, beacon, beacons, clock, cmds, reference, started, state


def two_ticks() -> SoloNode:
    node = started()
    for k in range(2):
        out = node.step([clock(k), state(k, 100.0, 0.0), beacon(B, k, 110.0, 0.0), beacon(C, k, 120.0, 0.0)],
                        0.01 * k)
        assert [c.k for c in cmds(out)] == [k]
    assert node.k == 1 and node.guessed_k == -1
    return node


def test_a_router_link_lost_mid_mission_makes_the_next_tick_a_guess() -> None:
    node = two_ticks()
    node.step([RouterReach(False)], 0.1)
    back = node.step([RouterReach(True)], 3.0)
    # Our newest beacon again: it may have been lost with the link, and peers place us by it for their next wait.
    assert [(b.id, b.k) for b in beacons(back)] == [(A, 1)]
    out = node.step([clock(2), state(2, 100.0, 0.0), beacon(B, 2, 110.0, 0.0), beacon(C, 2, 120.0, 0.0)], 3.1)
    assert [c.k for c in cmds(out)] == [2] and node.guessed_k == 2  # (tick 2's data may have been in flight)
    node.step([clock(3), state(3, 100.0, 0.0), beacon(B, 3, 110.0, 0.0), beacon(C, 3, 120.0, 0.0)], 3.2)
    assert node.k == 3 and node.guessed_k == 2  # (the first guess stays the one said)


def test_a_different_router_found_between_two_polls_is_a_link_lost_too() -> None:
    node = two_ticks()
    node.step([RouterReach(True)], 0.1)  # (a router restarted between two polls: UP with no DOWN before it)
    node.step([clock(2), state(2, 100.0, 0.0), beacon(B, 2, 110.0, 0.0), beacon(C, 2, 120.0, 0.0)], 0.2)
    assert node.k == 2 and node.guessed_k == 2


def test_a_link_change_before_the_first_clock_or_in_realtime_says_nothing() -> None:
    node = started()
    node.step([RouterReach(False)], 0.0)
    node.step([RouterReach(True)], 0.5)
    node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0), beacon(C, 0, 120.0, 0.0)], 0.6)
    assert node.k == 0 and node.guessed_k == -1
    rt = started()
    rt.step([clock(0, (A, B, C), mode="realtime", speed=1.0), state(0, 100.0, 0.0)], 0.0)
    rt.step([RouterReach(False)], 0.1)
    rt.step([state(1, 100.0, 0.0), beacon(B, 1, 110.0, 0.0), beacon(C, 1, 120.0, 0.0)], 0.2)
    assert rt.k == 1 and rt.guessed_k == -1


def test_tokens_that_go_with_our_router_do_not_shrink_the_wait_set() -> None:
    """The router dies while we wait for tick 2's beacons: every token it carried goes (the peers' and the
    world's) a moment before our session finds its link gone. The tick is not acted on without the peers: their
    tokens count as gone only `token_confirm_s` later, and not at all while our link is down; back, they come
    again with their beacons, and the command is the one planned with both."""
    node = two_ticks()
    assert not cmds(node.step([clock(2), state(2, 100.0, 0.0)], 0.10))  # (waiting for B and C)
    assert not cmds(node.step([left(B), left(C), world_token(False)], 0.11))  # (the router died: its tokens go)
    node.step([RouterReach(False)], 0.13)
    assert not cmds(node.step([], 2.0)) and node.k == 1
    node.step([RouterReach(True), joined(B), joined(C), world_token(True)], 3.0)
    out = node.step([beacon(B, 2, 110.0, 0.0), beacon(C, 2, 120.0, 0.0)], 3.1)
    want = reference(2, (100.0, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B]), Peer(C, 120.0, 0.0, RADIUS[C])])
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(2, *want)]


def test_a_peer_whose_token_goes_is_gone_token_confirm_s_later() -> None:
    """Agent C killed while we wait for tick 2 (our link stays up): we wait `token_confirm_s` for its token to come
    back, then act without it, which is no guess (its membership ended)."""
    node = two_ticks()
    node.step([clock(2), state(2, 100.0, 0.0), beacon(B, 2, 110.0, 0.0)], 0.10)
    assert not cmds(node.step([left(C)], 0.11))
    assert not cmds(node.step([], 0.11 + 0.5 * T.token_confirm_s))
    out = node.step([], 0.12 + T.token_confirm_s)
    assert [c.k for c in cmds(out)] == [2] and node.guessed_k == -1
