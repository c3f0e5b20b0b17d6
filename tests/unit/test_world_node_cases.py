"""The world's node (simworld/world.py) in the cases its mutation run (bench/mutation.py) found untested: its
own stall in realtime, what it tells the runtime to wait for, and the end statistics on known inputs. Driven
by hand as in test_world_node.py: inputs and times given, no zenoh."""

from __future__ import annotations

from dataclasses import replace

import pytest

from reconswarm.net.node import RouterReach, Stop
from reconswarm.net.wire import wire
from reconswarm.net.wire.wire import ClockMode
from reconswarm.scenario.model import Scenario
from simworld.robots import Robots
from simworld.world import Command, Phase, WorldNode
from tests.unit.test_world_node import (
    IDS,
    MONITOR,
    S,
    T,
    advance,
    commands,
    ended,
    run_ticks,
    started,
    ticks,
    tokens,
)

DT = S.meta.dt_s
PERIOD = DT / 10.0  # realtime at speed 10 (started())


def lasting(duration_s: float) -> Scenario:
    return replace(S, meta=replace(S.meta, duration_s=duration_s))


# ------------------------------------------------------------------------------------ its own stall


def test_a_realtime_world_stalled_itself_shifts_its_schedule_and_nobody_is_late() -> None:
    """SIGSTOP of a realtime world for 5 s while tick 0 waits for its due time: the tick is due 5 s later
    (not at once), tick 1 after it is due one period after that, and no tick counts as run late."""
    node = started(ClockMode.REALTIME, now=100.0)
    node.step([], 100.0)  # tick 0 out, due at 100 + period
    assert node.step([], 105.0) == [] and node.k == 0  # stalled 5 s: due now at 105 + period
    assert node.wake_at_s() == pytest.approx(105.0 + PERIOD)
    node.step([], 105.0 + PERIOD)
    assert node.k == 1
    (tick,) = ticks(node.step([], 105.0 + PERIOD))
    assert tick.clock.k == 1 and node.wake_at_s() == pytest.approx(105.0 + 2 * PERIOD)
    assert node.overruns == 0


# ------------------------------------------------------------------------------------ what it waits for


def test_one_message_can_move_it_on_before_the_start_and_while_it_holds_for_agents() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    node.step(tokens(IDS[1:]), 0.0)
    assert node.phase == Phase.READY and node.awaiting(0.0) == 1  # the last token or the monitor's
    node.step([*tokens(IDS[:1]), MONITOR], 0.1)
    assert node.started and node.awaiting(0.1) == 1  # (about to publish tick 0)
    node.step([], 0.1)
    advance(node, 0.1, 1.0, inputs=tokens(up=False))  # everyone gone: tick 0 stepped for nobody
    node.step([], 1.0)  # and the world holds for them
    assert node.phase == Phase.NO_AGENTS and node.awaiting(1.0) == 1  # one token back moves it on


def test_the_last_command_of_a_tick_asks_to_be_stepped_again_at_once() -> None:
    """Lockstep: once tick k's commands are all in, the robots move and tick k + 1 is due now: the runtime is
    told to step it again at once, not to sleep until some message comes."""
    node = started()
    node.step([], 0.0)
    node.step(commands(0, (1.0, 0.0), 0.2), 0.2)
    wake = node.wake_at_s()
    assert node.k == 1 and node.phase == Phase.TICK and wake is not None and wake <= 0.2


# ------------------------------------------------------------------------------------ the end statistics


def test_latency_percentiles_are_those_of_the_commands_arrival_in_ms_to_the_microsecond() -> None:
    """Realtime: state-to-command latency from the step that published tick 0 (t = 0) to each command's
    arrival: 1.0004, 2.0004, ... 10.0004 ms for the ten agents. Linear-interpolated percentiles of ten
    values: p50 = 5.5004 ms, p99 = 1.0004 + 0.99 * 9 = 9.9104 ms; reported to the microsecond."""
    node = started(ClockMode.REALTIME, now=0.0)
    node.step([], 0.0)
    at = [(j + 1.0004) / 1000.0 for j in range(len(IDS))]
    node.step([Command(wire.Cmd(a, 0, 0.1, 0.0), t) for a, t in zip(IDS, at, strict=True)], 0.011)
    st = node.stats()
    assert (st["latency_p50_ms"], st["latency_p99_ms"], st["latency_samples"]) == (5.5, 9.91, 10.0)


def test_a_robot_uncommanded_from_the_first_tick_is_said_at_t_0_whatever_comes_after() -> None:
    node = started()
    now = 0.0
    for k in range(2):  # ticks 0 and 1 stepped without agent IDS[3]'s command
        node.step([], now)
        node.step(commands(k, (1.0, 0.0), now, skip=(IDS[3],)), now)
        advance(node, now, now + T.step_timeout_s)
        now += T.step_timeout_s
        assert node.k == k + 1 and node.stats()["uncommanded_from_s"] == 0.0


def test_an_agent_that_struck_out_and_commands_again_starts_its_strikes_afresh() -> None:
    """Unresponsive after `strikes` (2) timeouts in a row; its command brings it back, and its next silence is
    one strike: the tick after that waits for it again (it is not unresponsive after a single timeout)."""
    node = started()
    late = IDS[5]
    now = 0.0
    for k in range(2):  # two timeouts: unresponsive
        node.step([], now)
        node.step(commands(k, (1.0, 0.0), now, skip=(late,)), now)
        advance(node, now, now + T.step_timeout_s)
        now += T.step_timeout_s
    assert late in node.unresponsive
    node.step([], now)  # tick 2: not waited for, but it commands again (another agent is late this once)
    node.step(commands(2, (1.0, 0.0), now, skip=(IDS[6],)), now)
    assert late not in node.unresponsive
    advance(node, now, now + T.step_timeout_s)
    now += T.step_timeout_s
    assert node.k == 3
    node.step([], now)  # tick 3: it is silent once
    node.step(commands(3, (1.0, 0.0), now, skip=(late,)), now)
    advance(node, now, now + T.step_timeout_s)
    now += T.step_timeout_s
    assert node.k == 4 and late not in node.unresponsive
    node.step([], now)  # tick 4 waits for it again
    node.step(commands(4, (1.0, 0.0), now, skip=(late,)), now)
    assert node.k == 4 and node.missing() == [late]


# ------------------------------------------------------------------------------------ what a tick says


def test_a_tick_and_a_tick_published_again_are_no_end() -> None:
    """Tick 0 as first published and as published again while it waits: not the end, no reason, no end
    statistics (only the mission's last clock carries them)."""
    node = started()
    first = ticks(node.step([], 0.0))
    again = ticks(node.step([], T.republish_s))
    for tick in first + again:
        assert tick.clock.k == 0 and not tick.clock.end and tick.clock.reason == "" and tick.clock.stats == {}
    assert len(again) == 1


def test_the_missed_deadline_ratio_is_missed_over_expected_and_0_before_any() -> None:
    node = started(ClockMode.REALTIME, now=0.0)
    st = node.stats()
    assert (st["missed_deadlines"], st["deadlines"], st["missed_deadline_ratio"]) == (0.0, 0.0, 0.0)
    now = 0.0
    for k in range(3):  # three ticks, ten agents each; agent IDS[0] misses tick 1 only
        node.step([], now)
        node.step(commands(k, (0.1, 0.0), now, skip=(IDS[0],) if k == 1 else ()), now)
        now += PERIOD
        node.step([], now)
        assert node.k == k + 1
    st = node.stats()
    assert (st["missed_deadlines"], st["deadlines"], st["missed_deadline_ratio"]) == (1.0, 30.0, 0.03333)


def test_a_lockstep_world_reports_no_deadlines_and_no_latency() -> None:
    node = started()
    node.step([], 0.0)
    node.step(commands(0, (1.0, 0.0), 0.01), 0.01)
    assert node.stats() == {"world_overruns": 0.0}



def test_a_tick_says_its_simulated_time_and_the_realtime_speed() -> None:
    lock = started()
    run_ticks(lock, range(0, 2), 0.0)
    (tick,) = ticks(lock.step([], 0.0))
    assert (tick.clock.k, tick.clock.t, tick.clock.mode, tick.clock.speed) == (2, 2 * DT, ClockMode.LOCKSTEP, 0.0)
    real = started(ClockMode.REALTIME, now=0.0)
    (tick,) = ticks(real.step([], 0.0))
    assert (tick.clock.mode, tick.clock.speed) == (ClockMode.REALTIME, 10.0)
    default = WorldNode(S, ClockMode.REALTIME, timing=T)  # realtime at wall-clock speed unless told
    default.step([*tokens(), MONITOR], 0.0)
    (tick,) = ticks(default.step([], 0.0))
    assert tick.clock.speed == 1.0 and default.wake_at_s() == pytest.approx(DT)


# ------------------------------------------------------------------------------------ when it wakes


def test_it_wakes_at_once_to_start_and_at_each_deadline_it_waits_for() -> None:
    """Once all are up, it asks to be stepped at once (tick 0 is due); a published lockstep tick wakes it to
    publish again (republish_s); holding for agents wakes it at the end of the grace, and that ends the
    mission when nobody came back."""
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    node.step([*tokens(), MONITOR], 2.0)
    wake = node.wake_at_s()
    assert node.started and wake is not None and wake <= 2.0
    node.step([], 2.0)
    assert node.wake_at_s() == pytest.approx(2.0 + T.republish_s)
    advance(node, 2.0, 3.0, inputs=tokens(up=False))
    node.step([], 3.0)
    assert node.phase == Phase.NO_AGENTS and node.wake_at_s() == pytest.approx(3.0 + T.no_agents_grace_s)
    assert advance(node, 3.0, 32.8) == [] and node.wake_at_s() == pytest.approx(3.0 + T.no_agents_grace_s)
    out = node.step([], 3.0 + T.no_agents_grace_s)  # stepped at its wake time: the grace is over
    assert ended(out) == "no agents"


def test_a_realtime_tick_at_its_due_time_is_stepped_and_the_next_is_due_at_once() -> None:
    node = started(ClockMode.REALTIME, now=0.0)
    node.step([], 0.0)
    assert node.step([], 0.5 * PERIOD) == [] and node.wake_at_s() == pytest.approx(PERIOD)
    node.step([], PERIOD)
    wake = node.wake_at_s()
    assert node.k == 1 and wake is not None and wake <= PERIOD


def test_every_tick_that_goes_out_late_is_an_overrun() -> None:
    node = started(ClockMode.REALTIME, now=0.0)
    node.step([], 0.0)
    for k in (1, 2):  # each tick stepped 5 periods after it was due
        node.step([], (5 * k) * PERIOD)
        assert node.k == k
        node.step([], (5 * k + 0.5) * PERIOD)  # tick k out, late
    assert node.overruns == 2 and node.stats()["world_overruns"] == 2.0


# ------------------------------------------------------------------------------------ signals and links


def test_a_stop_while_holding_for_agents_ends_the_mission_at_once() -> None:
    node = started()
    node.step([], 0.0)
    advance(node, 0.0, 1.0, inputs=tokens(up=False))
    node.step([], 1.0)
    assert node.phase == Phase.NO_AGENTS
    out = node.step([Stop()], 1.1)
    assert ended(out) is not None and ticks(out)[0].clock.end


def test_a_stop_while_realtime_waits_for_the_due_time_steps_the_tick_at_once() -> None:
    node = started(ClockMode.REALTIME, now=0.0)
    node.step([], 0.0)
    node.step([Stop()], 0.1 * PERIOD)
    assert node.k == 1  # not waiting for the due time
    out = node.step([], 0.2 * PERIOD)
    assert ended(out) == "stopped" and ticks(out)[0].clock.k == 1


def test_agents_back_after_a_hold_get_the_tick_as_an_ordinary_one() -> None:
    node = started()
    node.step([], 0.0)
    advance(node, 0.0, 1.0, inputs=tokens(up=False))
    node.step([], 1.0)
    (tick,) = ticks(node.step(tokens(IDS[:1]), 2.0))
    assert tick.clock.k == 1 and not tick.clock.end and tick.clock.reason == ""


def test_a_router_link_lost_and_back_before_the_start_still_starts() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    node.step([RouterReach(False)], 0.0)
    node.step([RouterReach(True)], 0.5)
    node.step([*tokens(), MONITOR], 1.0)
    assert node.started and [t.clock.k for t in ticks(node.step([], 1.0))] == [0]


def test_after_its_router_link_is_back_a_token_that_goes_is_judged_again() -> None:
    node = started()
    node.step([], 0.0)
    node.step([RouterReach(False)], 0.1)
    advance(node, 0.1, 0.2 + T.relink_settle_s, inputs=[RouterReach(True)])  # (the sessions settle meanwhile)
    now = 0.2 + T.relink_settle_s
    advance(node, now, now + 1.0, every_s=0.1, inputs=tokens(IDS[:1], up=False))
    assert IDS[0] not in node.alive and set(IDS[1:]) <= node.alive


# ------------------------------------------------------------------------------------ its settings


def test_the_mission_lasts_duration_s() -> None:
    short = lasting(0.2)  # 4 ticks of 0.05 s
    node = WorldNode(short, ClockMode.LOCKSTEP, 10.0, T)
    node.step([*tokens(), MONITOR], 0.0)
    now = run_ticks(node, range(0, 4), 0.0)
    out = node.step([], now)
    assert ended(out) == "duration" and ticks(out)[0].clock.k == 4


def test_a_token_without_commands_holds_a_tick_up_for_the_agents_own_wait_plus_1_s() -> None:
    """The grace a silent token gets is the agents' own wait for their peers (agent_wait_timeout_s) + 1 s:
    6 + 1 = 7 s here, not the 4 s of the default wait."""
    tm = replace(T, agent_wait_timeout_s=6.0, step_timeout_s=20.0)
    node = started(timing=tm)
    mute = IDS[1]
    node.step([], 0.0)
    node.step(commands(0, (1.0, 0.0), 0.0, skip=(mute,)), 0.0)
    advance(node, 0.0, 6.5)
    assert node.k == 0 and mute in node.alive
    advance(node, 6.5, 7.5)
    assert node.k == 1 and mute not in node.alive


def test_the_robots_given_are_the_ones_stepped() -> None:
    robots = Robots(S, T.hold_sim_s)
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T, robots=robots)
    assert node.robots is robots
    node.step([*tokens(), MONITOR], 0.0)
    run_ticks(node, range(0, 1), 0.0)
    assert not (robots.p == S.starts).all()  # the robots it holds moved


def test_a_realtime_agent_silent_2_s_of_wall_and_of_simulated_time_is_gone_though_its_token_stays() -> None:
    """Membership: an agent with a token counts until silent both fresh_s (2 s) of wall time and fresh_sim_s (2 s)
    of simulated time. Agent 2 commands ticks 0 to 2, then falls silent (its token stays); the others command
    every tick. At speed 10, 2.5 s of wall later the simulated time is 25 s on: agent 2 is gone, the others
    not."""
    node = started(ClockMode.REALTIME, now=0.0)
    mute, now = IDS[1], 0.0
    while now < 2.5:
        out = node.step([], now)
        for tick in ticks(out):
            skip = (mute,) if tick.clock.k > 2 else ()
            node.step(commands(tick.clock.k, (0.0, 0.0), now, skip), now)
        now = round(now + PERIOD, 6)
    assert node.k * DT > 20.0 and mute not in node.alive and node.alive == set(IDS) - {mute}
