"""What an agent heard (agent/heard.py), case by case: each peer's newest beacon (an older tick never replaces
it, the same tick does), its silence kept in the order of its times, robots its scan says are held near it,
the clock counting only peers whose token never came, stale places forgotten, and what a tick lacks."""

from __future__ import annotations

from agent.heard import Heard
from reconswarm.net.wire import wire
from tests.support import beacon


def test_a_peers_newest_beacon_is_kept_and_an_older_tick_does_not_replace_it() -> None:
    h = Heard(1)
    h.beacon(beacon(2, 5, 10.0, 0.0), 1.0)
    h.beacon(beacon(3, 4, 30.0, 0.0), 1.1)
    h.beacon(beacon(2, 3, 99.0, 0.0), 1.2)  # late: an older tick
    assert h.last_seen[2].k == 5 and h.last_seen[2].px == 10.0 and h.last_seen[3].px == 30.0
    h.beacon(beacon(2, 5, 11.0, 0.0), 1.3)  # the same tick again (a session that reconnected): the newest word
    assert h.last_seen[2].px == 11.0
    assert h.beacons[3] == {2: beacon(2, 3, 99.0, 0.0)} and h.beacons[5] == {2: beacon(2, 5, 11.0, 0.0)}


def test_silence_is_kept_in_the_order_of_each_peers_latest_word() -> None:
    h = Heard(1)
    h.beacon(beacon(2, 1, 0.0, 0.0), 1.0)
    h.beacon(beacon(3, 1, 0.0, 0.0), 2.0)
    h.beacon(beacon(2, 2, 0.0, 0.0), 3.0)  # peer 2 spoke last: it moves to the end
    assert list(h.heard.items()) == [(3, 2.0), (2, 3.0)]


def test_a_scan_places_the_held_robots_near_us_with_their_radius_and_time() -> None:
    h = Heard(1)
    scan = wire.Scan(1, 40, 2.0, (), ((1, 0.0, 0.0), (4, 55.0, 6.0), (99, 1.0, 1.0)))
    h.scan(scan, {1: 2.0, 4: 3.5})
    assert h.scans[40] is scan
    assert h.last_seen == {4: wire.Beacon(4, 40, 2.0, 55.0, 6.0, 3.5)}  # not ourselves, not an unknown id


def test_the_clock_counts_only_peers_whose_token_never_came_or_went() -> None:
    h = Heard(1)
    h.token(2, True, 5.0)
    h.token(3, True, 5.0)
    h.token(3, False, 6.0)
    h.clock(wire.Clock(0, 0.0, (1, 2, 3, 4)), 10.0)
    assert h.heard == {2: 5.0, 3: 5.0, 4: 10.0}  # 4: counted by the clock before its token came


def test_stale_places_of_live_peers_are_forgotten_from_the_given_tick_on() -> None:
    h = Heard(1)
    for aid, k in [(2, 9), (3, 10), (4, 3)]:
        h.token(aid, True, 0.0)
        h.beacon(beacon(aid, k, 10.0 * aid, 0.0), 1.0)
    h.beacon(beacon(5, 1, 0.0, 0.0), 1.0)  # no token: a lost robot stays where it was seen
    h.forget_stale(lambda b: b.id != 4, living={2, 3, 4, 5}, stale_k=10)
    assert set(h.last_seen) == {3, 5}  # 2: heard before tick 10; 4: out of our cells; 3: at tick 10 exactly


def test_what_a_tick_without_its_state_lacks_and_the_newest_clock() -> None:
    h = Heard(1)
    assert h.newest_clock() is None
    h.states[7] = wire.State(1, 7, 0.35, 0.0, 0.0, 0.0, 1.0, 0.0, None)
    h.clock(wire.Clock(9, 0.45, (1,)), 0.0)
    assert h.lacks(8, set(), {}, {}) == "tick 8: no state yet (newest state 7, newest clock 9)"
    assert h.newest_clock() == wire.Clock(9, 0.45, (1,))
