"""The agent node's waits (agent/node.py, lockstep) on their own clocks: the wait for a lost clock counts from
when the tick's state came (not from 0), the wait for peers gives up after agent_wait_timeout_s even while a
peer keeps talking (its beacon for the tick never comes), and a stuck tick's beacon goes out again after
beacon_again_s, then 2, 4, 8 x that (never at every step)."""

from __future__ import annotations

import dataclasses

from agent.node import AgentNode
from tests.unit.test_agent_node import A, B, S, T, beacon, beacons, clock, cmds, joined, state


def test_the_wait_for_a_lost_clock_counts_from_the_states_arrival() -> None:
    t0 = 50.0  # well into the run's wall time
    node = AgentNode(S, A, t0, T)
    node.step([joined(A)], t0)
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], t0)
    assert node.k == 0
    node.step([state(1, 100.1, 0.0)], t0 + 0.1)  # clock 1 lost
    assert not cmds(node.step([], t0 + 0.1 + 0.5 * T.agent_wait_timeout_s))
    assert [c.k for c in cmds(node.step([], t0 + 0.1 + T.agent_wait_timeout_s + 0.01))] == [1]


def test_the_wait_for_a_talking_peer_gives_up_after_the_wait_timeout() -> None:
    node = AgentNode(S, A, 0.0, T)
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
    node = AgentNode(S, A, 0.0, patient)
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
