"""What an agent heard (agent/heard.py): a peer the world's clock counts before its token came is heard from
the first clock that names it (its silence counts from then), whatever clocks follow; the text of what a
tick lacks."""

from __future__ import annotations

from agent.heard import Heard
from reconswarm.net.wire import wire


def clock(k: int, alive: tuple[int, ...]) -> wire.Clock:
    return wire.Clock(k, 0.05 * k, alive)


def test_a_peer_is_heard_from_the_first_clock_that_counts_it() -> None:
    h = Heard(1)
    h.clock(clock(0, (1, 2)), 10.0)
    assert h.heard == {2: 10.0}
    h.clock(clock(1, (1, 2)), 11.0)  # the same agents: nothing new
    assert h.heard == {2: 10.0}
    h.clock(clock(2, (1, 2, 3)), 12.0)  # agent 3 counted from now
    assert h.heard == {2: 10.0, 3: 12.0}
    h.clock(clock(3, (1, 2, 3)), 13.0)
    assert h.heard == {2: 10.0, 3: 12.0} and set(h.clocks) == {0, 1, 2, 3}


def test_a_peer_alive_or_gone_by_its_token_is_not_counted_by_the_clock() -> None:
    h = Heard(1)
    h.token(2, True, 5.0)  # heard from its token
    h.token(3, False, 5.0)  # gone before any clock (once not back within the confirmation)
    assert not h.confirm(5.2, 0.3) and h.gone == set() and h.confirm(5.31, 0.3) and h.gone == {3}
    h.clock(clock(0, (1, 2, 3)), 10.0)
    assert h.heard == {2: 5.0} and h.living(h.clocks[0]) == {1, 2}
    h.token(3, True, 11.0)  # back: heard from its token, and the same clock again counts nobody new
    h.clock(clock(1, (1, 2, 3)), 12.0)
    assert h.heard == {2: 5.0, 3: 11.0}


def test_what_a_tick_lacks() -> None:
    h = Heard(1)
    assert h.lacks(0, frozenset(), {}, {}) == "tick 0: no state yet (newest state None, newest clock None)"
    h.states[0] = wire.State(1, 0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0)
    h.beacon(wire.Beacon(2, 0, 0.0, 1.0, 0.0, 0.3, 0), 1.0)
    got = h.lacks(0, frozenset({2, 3}), {2: 1, 4: 2}, {2: {1: {}}})
    assert got == "tick 0: waiting for clock, beacons of [3], obstacle sets of [4]"
    h.clock(clock(0, (1, 2, 3)), 2.0)
    h.beacon(wire.Beacon(3, 0, 0.0, 2.0, 0.0, 0.3, 0), 2.0)
    assert h.lacks(0, frozenset({2, 3}), {2: 1}, {2: {1: {}}}) == "tick 0: waiting for nothing"
