"""Each role's policy of who is alive (reconswarm/net/trust/membership.py), as a state machine: joined, silent past the
role's threshold -> lost, token gone -> lost only as the policy says, back -> joined again. Thresholds from the
one `Timing`; their order across roles as the timing notes state it."""

from __future__ import annotations

import math

import pytest

from agent.heard import Heard
from reconswarm.net.node import Role
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.trust.membership import Membership, Policy, living, silent
from reconswarm.net.wire import wire

T = Timing()


def _clock(k: int, alive: tuple[int, ...]) -> wire.Clock:
    return wire.Clock(k=k, t=0.1 * k, mode=wire.ClockMode.LOCKSTEP, alive=alive)


def test_every_threshold_of_the_world_and_the_monitor_comes_from_timing() -> None:
    t = Timing(member_fresh_s=1.5, member_fresh_sim_s=2.5, member_grace_s=7.0, member_grace_sim_s=4.0,
               token_confirm_s=0.2, agent_wait_timeout_s=3.5, await_margin_s=0.5, peer_silent_s=2.75,
               relink_settle_s=6.0, realtime_peer_silent_s=0.8)
    assert Policy.world(t) == Policy(Role.WORLD, 1.5, 2.5, 7.0, 4.0, 0.2, 4.0, 6.0, 2.75, math.inf)
    assert Policy.monitor(t) == Policy(Role.MONITOR, 1.5, 2.5, 7.0, 4.0, 0.2, math.inf, 6.0, 0.0, math.inf)
    assert Policy.agent(t) == Policy(Role.AGENT, 2.75, math.inf, 2.75, math.inf, 0.0, math.inf, 0.0, 0.0, 0.8)


def test_the_default_thresholds_are_the_ones_every_role_ran_with() -> None:
    """World and monitor: fresh 2 s / 2 s, grace 10 s / 5 s, a token's end confirmed 0.3 s later; the world mutes
    a token that holds a tick up 4 s (an agent's own 3 s wait + 1 s); tokens have 10 s to come back once our
    router link is back, and 3 s after the world's own stall; an agent waits 3 s for a silent peer and, in
    realtime, plans with peers heard within 1 s (or 3 periods)."""
    assert Policy.world(TIMING) == Policy(Role.WORLD, 2.0, 2.0, 10.0, 5.0, 0.3, 4.0, 10.0, 3.0, math.inf)
    assert Policy.monitor(TIMING) == Policy(Role.MONITOR, 2.0, 2.0, 10.0, 5.0, 0.3, math.inf, 10.0, 0.0, math.inf)
    assert Policy.agent(TIMING) == Policy(Role.AGENT, 3.0, math.inf, 3.0, math.inf, 0.0, math.inf, 0.0, 0.0, 1.0)


def test_the_thresholds_are_ordered_across_roles() -> None:
    lease_s = TIMING.lease_ms / 1000
    assert TIMING.peer_silent_s > lease_s and TIMING.agent_wait_timeout_s > lease_s  # a gone peer leaves by its token
    assert TIMING.telemetry_s < TIMING.member_fresh_s  # the agent's report is the monitor's heartbeat
    assert TIMING.ros2_stop_every_s < TIMING.member_fresh_s  # a stop is the world's heartbeat in ROS 2 mode
    assert Policy.world(TIMING).await_grace_s > TIMING.agent_wait_timeout_s  # an agent gives up on its peers first


@pytest.mark.parametrize("policy", [Policy.world(T), Policy.monitor(T)], ids=["world", "monitor"])
def test_world_and_monitor_joined_silent_lost_and_back(policy: Policy) -> None:
    m = Membership(policy)
    m.token(1, True, 0.0, 0.0)
    assert m.alive_ids(0.0, 0.0) == [1]  # joined: before the start a token alone counts
    m.start(1.0, 0.0)
    m.data(1, 2.0, 0.1)
    assert m.alive_ids(2.0 + policy.fresh_s, 0.1 + policy.fresh_sim_s) == [1]  # silent, bounds included
    assert m.alive_ids(2.0 + policy.fresh_s + 0.01, 0.1 + policy.fresh_sim_s + 0.01) == []  # silent in both: lost
    m.data(1, 5.0, 3.0)
    assert m.alive_ids(5.0, 3.0) == [1]  # its data again: back


@pytest.mark.parametrize("policy", [Policy.world(T), Policy.monitor(T)], ids=["world", "monitor"])
def test_world_and_monitor_a_token_that_goes_is_lost_confirm_s_later_unless_back(policy: Policy) -> None:
    m = Membership(policy)
    for a in (1, 2):
        m.token(a, True, 0.0, 0.0)
    m.start(0.0, 0.0)
    m.token(1, False, 1.0, 0.1)
    m.token(2, False, 1.0, 0.1)
    assert m.alive_ids(1.0 + policy.confirm_s - 0.01, 0.1) == [1, 2]  # not yet confirmed
    m.token(2, True, 1.0 + policy.confirm_s - 0.01, 0.1)  # 2 back in time: never gone
    assert m.alive_ids(1.0 + policy.confirm_s, 0.1) == [2]  # 1 lost
    m.token(1, True, 2.0, 0.2)
    assert m.alive_ids(2.0, 0.2) == [1, 2]  # 1 back: a new token's grace
    assert m.alive_ids(2.0 + policy.grace_s + 0.01, 0.2 + policy.grace_sim_s + 0.01) == []  # never heard: lost


def test_only_the_worlds_policy_stops_counting_a_token_that_holds_a_tick_up() -> None:
    world, monitor = Membership(Policy.world(T)), Membership(Policy.monitor(T))
    for m in (world, monitor):
        m.token(1, True, 0.0, 0.0)
        m.start(0.0, 0.0)
        m.awaited(1, 0.0, Policy.world(T).await_grace_s + 0.01)  # sim stands while a tick waits
    assert world.alive_ids(4.5, 0.0) == [] and monitor.alive_ids(4.5, 0.0) == [1]
    world.data(1, 4.6, 0.0)
    assert world.alive_ids(4.6, 0.0) == [1]  # its command came: counted again


def test_agent_joined_lost_by_its_token_once_confirmed_and_back() -> None:
    h = Heard(0)
    h.token(1, True, 0.0)
    h.token(2, True, 0.0)
    assert h.living(None) == {1, 2}  # joined: by tokens until a clock says
    c = _clock(1, (0, 1, 2))
    h.clock(c, 0.1)
    assert h.living(c) == {0, 1, 2}
    h.token(2, False, 0.2)
    assert h.living(c) == {0, 1, 2}  # token going: not judged before token_confirm_s (a dying router's news)
    assert not h.confirm(0.2 + T.token_confirm_s / 2, T.token_confirm_s)
    assert h.confirm(0.2 + T.token_confirm_s, T.token_confirm_s)
    assert h.living(c) == {0, 1}  # token gone: lost, though the clock still counts it
    assert h.living(None) == {1}
    h.token(2, True, 0.3)
    assert h.living(c) == {0, 1, 2}  # back


def test_agent_a_silent_peer_is_not_waited_for_but_lost_only_when_the_clock_drops_it() -> None:
    p = Policy.agent(T)
    assert not silent(p, 1.0, 1.0 + p.fresh_s - 0.01)
    assert silent(p, 1.0, 1.0 + p.fresh_s)  # silent past peer_silent_s: not waited for
    tokens, gone = {1, 2}, set[int]()
    assert living(tokens, gone, frozenset({0, 1, 2})) == {0, 1, 2}  # silence alone does not make it lost
    assert living(tokens, gone, frozenset({0, 1})) == {0, 1}  # the world's clock stopped counting 2: lost


def test_agent_living_returns_the_sets_it_is_given_without_a_copy() -> None:
    tokens, counted = {1, 2}, frozenset({1, 2, 3})
    assert living(tokens, set(), None) is tokens
    assert living(tokens, set(), counted) is counted
    assert living(tokens, {3}, counted) == {1, 2}
