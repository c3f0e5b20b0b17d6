"""Who is alive (reconswarm/net/trust/membership.py), rule by rule with wall and simulated time on different scales
(wall about 1,000 s of monotonic time, sim a few seconds), so that a rule reading one clock for the other shows:
fresh data in either clock, the grace after a token appears, the bounds inclusive, and the guards of `awaited`."""

from __future__ import annotations

from reconswarm.net.timing import Timing
from reconswarm.net.trust.membership import Membership, Policy

P = Policy.world(Timing(token_confirm_s=0.0))  # fresh 2 s / 2 s, grace 10 s / 5 s, await 4 s, confirmed at once


def _started(wall: float = 1000.0, sim: float = 0.0) -> Membership:
    m = Membership(P)
    m.token(1, True, wall, sim)
    m.start(wall, sim)
    return m


def test_fresh_data_in_either_clock_keeps_an_agent_alive_bounds_included() -> None:
    m = _started()
    m.data(1, 1001.0, 0.5)
    assert m.alive(1, 1003.0, 3.0)  # 2.0 s of wall since its data: still fresh (2.5 s of sim: not)
    assert m.alive(1, 1010.0, 2.5)  # 9 s of wall (the world stalled) but 2.0 s of sim: fresh
    assert not m.alive(1, 1010.0, 2.75)  # silent in both clocks


def test_data_at_the_very_moment_its_token_appeared_counts_as_heard_since() -> None:
    m = _started()
    m.data(1, 1000.0, 0.0)
    assert not m.alive(1, 1003.0, 3.0)  # judged by its data (silent 3 s), not by the 10 s grace of a new token


def test_data_from_before_a_token_came_back_does_not_count() -> None:
    m = _started()
    m.data(1, 1001.0, 0.05)
    m.token(1, False, 1002.0, 0.1)  # gone (confirmed at once)
    assert not m.alive(1, 1002.0, 0.1)
    m.token(1, True, 1005.0, 3.0)  # back: the grace of a new token, from (1005, 3.0)
    assert m.alive(1, 1006.0, 3.05)  # its old data (4 s ago) would say silent; the grace says alive


def test_the_grace_of_a_new_token_counts_from_when_it_appeared_in_each_clock() -> None:
    m = Membership(P)
    m.start(990.0, 2.0)
    m.token(1, True, 1000.0, 7.0)  # joins later: the grace from (1000, 7)
    assert m.alive(1, 1010.0, 13.0)  # 10.0 s of wall: included
    assert not m.alive(1, 1010.5, 13.0)
    assert m.alive(1, 1020.0, 12.0)  # 20 s of wall, 5.0 s of sim: included
    assert not m.alive(1, 1020.0, 12.25)


def test_the_grace_in_wall_time_when_simulated_time_runs_ahead_of_it() -> None:
    m = Membership(P)
    m.start(4.0, 100.0)  # (a monotonic clock a few seconds old, a mission far into simulated time)
    m.token(1, True, 5.0, 200.0)
    assert m.alive(1, 15.0, 201.0)
    assert not m.alive(1, 20.0, 206.0)  # 15 s of wall and 6 s of sim since the token: gone


def test_a_muted_agent_whose_token_goes_and_comes_back_is_judged_afresh() -> None:
    m = _started()
    m.awaited(1, 1000.0, 1005.0)  # nothing from it since the wait began, 5 s > 4 s: its token stops counting
    assert not m.alive(1, 1005.0, 0.0)
    m.token(1, False, 1006.0, 0.0)
    m.token(1, True, 1007.0, 0.0)
    assert m.alive(1, 1008.0, 0.0)  # a new token: the grace, not the old mute


def test_awaited_mutes_only_an_agent_silent_since_the_wait_began() -> None:
    m = _started()
    m.data(1, 1002.0, 0.1)  # heard after the wait began (1001)
    m.awaited(1, 1001.0, 1006.0)
    assert m.alive(1, 1006.0, 1.1)  # (fresh in sim time)
    m = _started()
    m.data(1, 1001.0, 0.1)  # heard at the very moment the wait began: counts as since
    m.awaited(1, 1001.0, 1006.0)
    assert m.alive(1, 1006.0, 1.1)
    m = _started()
    m.data(1, 1000.5, 0.1)  # heard before the wait began
    m.awaited(1, 1001.0, 1006.0)
    assert not m.alive(1, 1006.0, 1.1)


def test_awaited_waits_out_a_settle_and_mutes_from_its_end_on() -> None:
    m = _started()
    m.settle(1010.0)
    m.awaited(1, 1000.0, 1005.0)  # the caller itself stalled until 1010: nobody is judged late before then
    assert m.alive(1, 1005.0, 0.0)
    m = _started()
    m.settle(1005.0)
    m.awaited(1, 1000.0, 1005.0)  # at the settle's end: judged
    assert not m.alive(1, 1005.0, 0.0)


def test_awaited_before_the_start_mutes_nobody() -> None:
    m = Membership(P)
    m.token(1, True, 1000.0, 0.0)
    m.awaited(1, 1000.0, 1100.0)
    m.start(1101.0, 0.0)
    assert m.alive(1, 1101.0, 0.0)  # the grace after the start, not a mute from before it
