"""Our session losing its router (or finding a different one) mid-mission in lockstep: whatever was in flight to
us meanwhile is lost, and nothing tells which of it a tick needed (a peer's beacon from outside our wait set is
re-sent by nobody): the next tick we act on is a guess, said in our reports (`guessed_k`), so the summary says
`deterministic: false` from then. Before the mission's first clock, and in realtime, a link change says nothing."""

from __future__ import annotations

from agent.node import AgentNode
from reconswarm.net.node import RouterLink
from tests.unit.test_agent_node import A, B, C, beacon, clock, cmds, started, state


def two_ticks() -> AgentNode:
    node = started()
    for k in range(2):
        out = node.step([clock(k), state(k, 100.0, 0.0), beacon(B, k, 200.0, 0.0), beacon(C, k, 300.0, 0.0)],
                        0.01 * k)
        assert [c.k for c in cmds(out)] == [k]
    assert node.k == 1 and node.guessed_k == -1
    return node


def test_a_router_link_lost_mid_mission_makes_the_next_tick_a_guess() -> None:
    node = two_ticks()
    node.step([RouterLink(False)], 0.1)
    node.step([RouterLink(True)], 3.0)
    out = node.step([clock(2), state(2, 100.0, 0.0), beacon(B, 2, 200.0, 0.0), beacon(C, 2, 300.0, 0.0)], 3.1)
    assert [c.k for c in cmds(out)] == [2] and node.guessed_k == 2  # (tick 2's data may have been in flight)
    node.step([clock(3), state(3, 100.0, 0.0), beacon(B, 3, 200.0, 0.0), beacon(C, 3, 300.0, 0.0)], 3.2)
    assert node.k == 3 and node.guessed_k == 2  # (the first guess stays the one said)


def test_a_different_router_found_between_two_polls_is_a_link_lost_too() -> None:
    node = two_ticks()
    node.step([RouterLink(True)], 0.1)  # (a router restarted between two polls: UP with no DOWN before it)
    node.step([clock(2), state(2, 100.0, 0.0), beacon(B, 2, 200.0, 0.0), beacon(C, 2, 300.0, 0.0)], 0.2)
    assert node.k == 2 and node.guessed_k == 2


def test_a_link_change_before_the_first_clock_or_in_realtime_says_nothing() -> None:
    node = started()
    node.step([RouterLink(False)], 0.0)
    node.step([RouterLink(True)], 0.5)
    node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 200.0, 0.0), beacon(C, 0, 300.0, 0.0)], 0.6)
    assert node.k == 0 and node.guessed_k == -1
    rt = started()
    rt.step([clock(0, (A, B, C), mode="realtime", speed=1.0), state(0, 100.0, 0.0)], 0.0)
    rt.step([RouterLink(False)], 0.1)
    rt.step([state(1, 100.0, 0.0), beacon(B, 1, 200.0, 0.0), beacon(C, 1, 300.0, 0.0)], 0.2)
    assert rt.k == 1 and rt.guessed_k == -1
