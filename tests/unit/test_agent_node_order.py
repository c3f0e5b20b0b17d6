"""Lockstep's wait set against the order a peer's beacon of tick k-1 and our state of k come in (agent/node.py,
agent/neighbours.py; issue 52). The wait set of k is built from the peers' beacons of k-1 in when our state of k
comes: the host hands them over no later than that state (each was put before its agent's command of k-1, which
the world waits for before any state of k: tests/unit/test_agent_host_order.py). Given that order, a peer
closing in is waited for at the tick it may come within reach, and the tick equals the engine's. A beacon of
k-1 handed over after our state of k (the order a host whose subscriptions each ran on a thread of their own
could give) leaves the peer out, and its beacon of k within reach is said: lockstep is then a guess."""

from __future__ import annotations

from reconswarm.net.wire import wire
from tests.unit.solo import SoloNode
from tests.unit.test_agent_node import DT, RADIUS, A, clock, cmds, started, state

D = 4  # a peer closing in on us along +x (far at its start in the scenario)


def closing(node: SoloNode) -> tuple[float, list[wire.Beacon]]:
    """D's beacons of ticks 0..3: one step (V dt) closer each tick, from just beyond where tick 1 could wait for it
    to within reach of us at tick 3 (we step once towards it, from tick 2 to 3). Also: our head x at tick 3."""
    reach, step = node.nb.grid.reach_m, node.nb.grid.step_m
    xs = [100.0 + reach + (3.6 - k) * step for k in range(4)]
    assert node.nb.grid.matter_m < xs[1] - 100.0 and xs[2] - 100.0 < node.nb.grid.matter_m  # (waited for at 3)
    return 100.0 + step, [wire.Beacon(D, k, k * DT, x, 0.0, RADIUS[D], 0) for k, x in enumerate(xs)]


def first_ticks(node: SoloNode, d: list[wire.Beacon]) -> None:
    """Ticks 0 and 1 with D's beacons of 0 and 1 in, our head at x = 100: D is not waited for (too far)."""
    for k in range(2):
        node.step([d[k], clock(k, (A, D)), state(k, 100.0, 0.0)], 0.05 * k)
        assert node.k == k and node.guessed_k == -1


def test_a_peer_closing_in_is_waited_for_when_its_beacon_of_the_tick_before_came_with_our_state() -> None:
    node = started(peers=(D,))
    x3, d = closing(node)
    first_ticks(node, d)
    node.step([d[2], clock(2, (A, D)), state(2, 100.0, 0.0)], 0.1)  # (D's beacon of 2 in no later than our state)
    assert node.k == 2
    assert not cmds(node.step([clock(3, (A, D)), state(3, x3, 0.0)], 0.15))  # tick 3 waits for D
    assert [c.k for c in cmds(node.step([d[3]], 0.16))] == [3]  # then acts, with D's beacon of 3
    assert node.guessed_k == -1


def test_a_beacon_of_the_tick_before_handed_over_after_our_state_leaves_the_peer_out_and_is_said() -> None:
    node = started(peers=(D,))
    x3, d = closing(node)
    first_ticks(node, d)
    node.step([clock(2, (A, D)), state(2, 100.0, 0.0)], 0.1)
    node.step([clock(3, (A, D)), state(3, x3, 0.0)], 0.15)
    assert node.k == 3  # acted at 3 without D: its beacon of 2 was not in when the wait set was built
    node.step([d[2], d[3]], 0.16)
    assert node.guessed_k == 3  # D's beacon of 3 within reach: the tick was a guess, and the node says so
