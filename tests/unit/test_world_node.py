"""The world's node (simworld/world.py) against its state machine, driven by hand: inputs and times given, no
zenoh, no processes. What it is given is what its process's gate admitted; what it returns is what goes out."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pytest

from reconswarm.errors import ProcessFailure
from reconswarm.net.node import Exit, Invalid, Role, RouterReach, Stop, Token
from reconswarm.net.timing import Timing
from reconswarm.net.wire import wire
from reconswarm.net.wire.wire import ClockMode
from reconswarm.plant import unicycle
from reconswarm.scenario.model import load
from simworld.ros2_io import ros2_world
from simworld.world import Command, Phase, WorldInput, WorldNode, WorldOutput
from tests.support import PAPER

# A step times out before a silent token's grace (Membership.awaited: agent_wait_timeout_s + 1 = 4 s) runs out.
T = Timing(start_timeout_s=10.0, republish_s=0.5, step_timeout_s=3.0, strikes=2, hold_sim_s=0.2, no_agents_grace_s=30.0)
S = load(PAPER)
IDS = [a.id for a in S.agents]
MONITOR = Token(Role.MONITOR, True)


def tokens(ids: Sequence[int] | None = None, up: bool = True) -> list[WorldInput]:
    return [Token(Role.AGENT, up, a) for a in (IDS if ids is None else ids)]


def commands(k: int, u: tuple[float, float], at: float, skip: tuple[int, ...] = ()) -> list[WorldInput]:
    return [Command(wire.Cmd(a, k, *u), at) for a in IDS if a not in skip]


@dataclass
class Tick:
    clock: wire.Clock
    truth: wire.Truth
    states: list[wire.State]


def ticks(out: Sequence[WorldOutput]) -> list[Tick]:
    """The ticks in a step's outputs, each its clock, states and truth in that order."""
    got: list[Tick] = []
    for m in out:
        if isinstance(m, wire.Clock):
            got.append(Tick(m, None, []))  # type: ignore[arg-type]
        elif isinstance(m, wire.Truth):
            assert got and got[-1].truth is None and len(got[-1].states) == len(IDS)
            got[-1].truth = m
        elif isinstance(m, wire.State):
            assert got and got[-1].truth is None
            got[-1].states.append(m)
    assert all(len(t.states) == len(IDS) and t.truth is not None for t in got)
    return got


def ended(out: Sequence[WorldOutput]) -> str | None:
    """The end reason if the step ended the mission (its Exit, last)."""
    exits = [m for m in out if isinstance(m, Exit)]
    assert len(exits) <= 1 and (not exits or out[-1] is exits[0])
    return exits[0].reason if exits else None


def started(clock: ClockMode = ClockMode.LOCKSTEP, now: float = 0.0, timing: Timing = T) -> WorldNode:
    node = WorldNode(S, clock, 10.0, timing)
    assert node.step([*tokens(), MONITOR], now) == [] and node.started
    return node


def advance(node: WorldNode, t0: float, t1: float, every_s: float = 0.5,
            inputs: Sequence[WorldInput] = ()) -> list[WorldOutput]:
    """Step every every_s from t0 to t1 (as the runtime would, so the world never looks stalled itself), with
    `inputs` at the first step; every output, up to the mission's end."""
    outs: list[WorldOutput] = []
    t, first = t0, list(inputs)
    while True:
        t = min(t1, t + every_s)
        out = node.step(first, t)
        first = []
        outs += out
        if t >= t1 or ended(out):
            return outs


def run_ticks(node: WorldNode, ks: range, now: float, skip: tuple[int, ...] = ()) -> float:
    """Publish and command each tick (the `skip`ped agents silent: each tick then times out)."""
    for k in ks:
        assert [t.clock.k for t in ticks(node.step([], now))] == [k]
        node.step(commands(k, (1.0, 0.0), now, skip), now)
        if skip:
            advance(node, now, now + T.step_timeout_s)
            now += T.step_timeout_s
        assert node.k == k + 1
    return now


# ------------------------------------------------------------------------------------------ barrier


def test_barrier_waits_for_every_agent_and_the_monitor() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    assert node.step(tokens(IDS[:-1]), 0.0) == [] and not node.started
    assert node.wake_at_s() == pytest.approx(10.0)
    assert node.step(tokens(IDS[-1:]), 1.0) == [] and not node.started  # the monitor is still missing
    assert node.step([MONITOR], 2.0) == [] and node.started and node.phase == Phase.TICK


def test_barrier_times_out_naming_who_is_missing() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    node.step(tokens(IDS[1:]), 0.0)
    node.step([], 9.9)
    with pytest.raises(ProcessFailure, match=f"agent {IDS[0]}, monitor"):
        node.step([], 10.5)


def test_a_token_of_an_agent_not_in_the_scenario_counts_for_nothing() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    node.step([*tokens(IDS[1:]), Token(Role.AGENT, True, 999), MONITOR], 0.0)
    assert not node.started and 999 not in node.alive


def test_stopped_before_the_start() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    assert node.step([Stop()], 0.0) == [Exit(0, "stopped")] and not node.started


# ------------------------------------------------------------------------------------------ lockstep


def test_lockstep_waits_for_every_command_then_integrates() -> None:
    node = started()
    out = node.step([], 0.0)
    assert [type(m) for m in out] == [wire.Clock] + [wire.State] * len(IDS) + [wire.Truth]  # the order it goes out
    (tick,) = ticks(out)
    assert tick.clock.k == 0 and tick.clock.alive == tuple(sorted(IDS)) and not tick.clock.end
    assert [m.id for m in tick.states] == IDS and tick.truth.ids == tuple(IDS)
    assert all(m.scan.points for m in tick.states if m.scan is not None)
    p0, th0 = node.robots.p.copy(), node.robots.theta.copy()
    assert node.awaiting(0.0) == len(IDS)  # the runtime sleeps until every command could be in
    assert node.step(commands(0, (0.5, 0.2), 0.01, skip=(IDS[3],)), 0.02) == [] and node.k == 0  # one missing
    assert node.awaiting(0.02) == 1 and node.missing() == [IDS[3]]
    node.step(commands(0, (0.5, 0.2), 0.03)[3:4], 0.04)
    assert node.k == 1
    # the command is the unicycle's (v, ω) = (0.5 m/s, 0.2 rad/s); eq. 3 makes it the head point's velocity
    u = np.stack([0.5 * np.cos(th0) - S.head_offsets * 0.2 * np.sin(th0),
                  0.5 * np.sin(th0) + S.head_offsets * 0.2 * np.cos(th0)], axis=1)
    p1, th1 = unicycle.step(p0, th0, u, S.head_offsets, S.meta.dt_s, S.world.max_speed_mps,
                            S.world.max_turn_rate_radps)
    assert np.array_equal(node.robots.p, p1) and np.array_equal(node.robots.theta, th1)
    (tick1,) = ticks(node.step([], 0.05))
    assert tick1.clock.k == 1 and tick1.truth.px == tuple(p1[:, 0].tolist())


def test_a_waiting_tick_is_published_again_every_republish_s() -> None:
    node = started()
    node.step([], 0.0)
    assert node.step([], 0.4) == [] and node.wake_at_s() == pytest.approx(0.5)
    assert [t.clock.k for t in ticks(node.step([], 0.5))] == [0] and node.k == 0
    assert node.step([], 0.9) == []
    assert [t.clock.k for t in ticks(node.step([], 1.0))] == [0]


def test_a_silent_robot_is_held_then_stopped_and_strikes_out() -> None:
    node = started()
    silent = IDS[2]
    i = IDS.index(silent)
    now = 0.0
    node.step([], now)
    node.step(commands(0, (1.0, 0.0), now), now)
    trail = [node.robots.p[i].copy()]
    hold_ticks = round(T.hold_sim_s / S.meta.dt_s)
    for k in range(1, 3):
        node.step([], now)  # publish tick k
        node.step(commands(k, (1.0, 0.0), now, skip=(silent,)), now)
        assert node.missing() == [silent]
        advance(node, now, now + T.step_timeout_s - 0.5)
        assert node.k == k  # still waiting
        advance(node, now + T.step_timeout_s - 0.5, now + T.step_timeout_s)  # the step times out: held
        now += T.step_timeout_s
        assert node.k == k + 1 and silent in node.alive  # (its token is there, within the grace)
        trail.append(node.robots.p[i].copy())
    assert node.strikes[silent] == 2 and silent in node.unresponsive
    # Not waited for any more: the others' commands are enough.
    for k in range(3, 3 + hold_ticks + 2):
        node.step([], now)
        node.step(commands(k, (1.0, 0.0), now, skip=(silent,)), now)
        assert node.k == k + 1
        trail.append(node.robots.p[i].copy())
    moved = [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(trail)]
    assert all(m > 0 for m in moved[:hold_ticks])  # the last command is held for hold_sim_s
    assert all(m == 0 for m in moved[hold_ticks:])  # then the robot stops
    node.step([], now)
    node.step([Command(wire.Cmd(silent, node.k, 0.0, 0.0), now)], now)
    assert silent not in node.unresponsive and silent not in node.strikes


def test_late_commands_count_as_the_latest() -> None:
    node = started()
    node.step([], 0.0)
    node.step(commands(0, (1.0, 0.0), 0.0, skip=(IDS[0],)), 0.0)
    advance(node, 0.0, T.step_timeout_s)  # timed out without agent IDS[0]
    assert node.k == 1
    now = T.step_timeout_s + 0.1
    node.step([Command(wire.Cmd(IDS[0], 0, 0.3, 0.0), now)], now)  # tick 0's command, late (tick 1 goes out)
    node.step(commands(1, (1.0, 0.0), now + 0.1, skip=(IDS[0],)), now + 0.1)
    advance(node, now + 0.1, now + 0.1 + T.step_timeout_s)
    # held as the head point's velocity u = M(θ_0) [0.3, 0] at the heading of tick 0, the one it was planned at
    th0 = S.headings[0]
    assert node.robots.held[0].tolist() == [0.3 * np.cos(th0), 0.3 * np.sin(th0)] and node.robots.held_k[0] == 0


def test_invalid_messages_and_commands_of_unknown_agents_are_counted_on_the_clock() -> None:
    node = started()
    node.step([Invalid("k", "bad"), Invalid("k", "worse"), Command(wire.Cmd(999, 0, 0.0, 0.0), 0.0)], 0.0)
    assert node.rejected == 3 and 999 not in node.alive
    (tick,) = ticks(node.step([], 0.5))  # (tick 0 again)
    assert tick.clock.rejected == 3


# ----------------------------------------------------------------------------------------- membership


def test_a_token_without_commands_stops_holding_a_tick_up_and_commands_bring_it_back() -> None:
    """Alive = token AND own commands: a token anyone can declare does not hold a lockstep tick up past the grace
    (agent_wait_timeout_s + 1 = 4 s), no step times out for it, and its next command counts it in again."""
    tm = replace(T, step_timeout_s=5.0)
    node = started(timing=tm)
    mute = IDS[1]
    node.step([], 0.0)
    node.step(commands(0, (1.0, 0.0), 0.0, skip=(mute,)), 0.0)
    advance(node, 0.0, 4.0)
    assert node.k == 0 and mute in node.alive
    advance(node, 4.0, 4.5)
    assert node.k == 1 and mute not in node.alive and not node.strikes  # before the step timeout (5 s)
    (tick,) = ticks(node.step([], 4.5))
    assert mute not in tick.clock.alive
    node.step([*commands(1, (1.0, 0.0), 4.6)], 4.6)
    assert mute in node.alive and node.k == 2  # its command: alive again (tick 1 waited for nobody muted)
    (tick,) = ticks(node.step([], 4.7))
    assert mute in tick.clock.alive


def test_a_token_that_goes_is_gone_once_confirmed_and_commands_alone_do_not_count() -> None:
    node = started()
    node.step([], 0.0)
    gone, flap = IDS[0], IDS[1]
    node.step([*tokens([gone, flap], up=False)], 0.1)
    assert {gone, flap} <= node.alive  # not yet confirmed (token_confirm_s = 0.3 s)
    node.step(tokens([flap]), 0.2)  # back within confirm_s: never gone
    node.step(commands(0, (1.0, 0.0), 0.4), 0.4)  # its commands keep coming, but its token is gone
    assert gone not in node.alive and flap in node.alive and node.k == 1
    (tick,) = ticks(node.step([], 0.5))
    assert gone not in tick.clock.alive and tick.clock.alive == tuple(sorted(set(IDS) - {gone}))


def test_in_ros2_mode_a_stop_dated_stale_keeps_its_agent_alive_and_moves_nothing() -> None:
    """An agent behind the clock sends no late plan, only a stop every 0.5 s, which the plant dates stale
    (simworld/ros2_io.py `Ros2IO.dated`): the world still counts it alive and its robot stands; an agent that
    never sends anything is lost once the start's grace is over (10 s: `member_grace_s`), its robot held."""
    node = ros2_world(S, speed=1.0, timing=T)
    assert node.step([*tokens(), MONITOR], 0.0) == [] and node.started
    stopper, silent = IDS[0], IDS[1]
    stale = 2 * node.robots.hold_ticks + 4  # (Ros2IO.keep_ticks)
    t, stood = 0.0, []
    while t < 11.0:
        t = round(t + 0.025, 3)
        inputs = commands(node.k, (0.5, 0.0), t, skip=(stopper, silent))
        if t % 0.5 == 0:
            inputs.append(Command(wire.Cmd(stopper, node.k - stale, 0.0, 0.0), t))
        node.step(inputs, t)
        stood.append(node.robots.p[IDS.index(stopper)].copy())
        if t == 9.0:
            assert {stopper, silent} <= node.alive  # (the start's grace)
    assert node.k >= 200 and stopper in node.alive and silent not in node.alive
    assert all((p == stood[0]).all() for p in stood)  # never moved: no stop it sent was applied, none needed


def test_no_agents_holds_then_ends_or_goes_on() -> None:
    node = started()
    assert ticks(node.step(tokens(up=False), 0.0))  # tick 0 out: the tokens' going is not confirmed yet
    advance(node, 0.0, 1.0)  # gone: nobody to wait for, tick 0 is stepped, and nobody is reachable
    assert node.k == 1 and node.phase == Phase.NO_AGENTS and not node.alive
    assert node.wake_at_s() == pytest.approx(1.0 + T.no_agents_grace_s)
    assert advance(node, 1.0, 10.0) == []
    assert [t.clock.k for t in ticks(node.step(tokens(IDS[:1]), 10.5))] == [1]  # back: the tick goes out
    advance(node, 10.5, 16.0, inputs=tokens(IDS[:1], up=False))  # nobody left to wait for: next tick
    assert node.k == 2 and node.phase == Phase.NO_AGENTS
    out = advance(node, 16.0, 50.0)
    assert ended(out) == "no agents"
    (tick,) = ticks(out)
    assert tick.clock.end and tick.clock.reason == "no agents"


def test_a_world_stalled_itself_waits_afresh_keeps_flapping_tokens_and_stays_in_lockstep() -> None:
    """SIGSTOP of simworld: when it runs again, no step has timed out (nobody was late but the world), the
    tick goes out again at once, and every token that flaps meanwhile is kept."""
    node = started()
    node.step([], 0.0)
    node.step(commands(0, (0.5, 0.0), 0.0, skip=(IDS[0], IDS[1])), 0.0)
    out = node.step(tokens(up=False), 10.0)  # 10 s later; the world's own session reconnects: tokens go
    assert [t.clock.k for t in ticks(out)] == [0] and node.k == 0 and not node.strikes
    assert node.missing() == [IDS[0], IDS[1]] and node.alive == set(IDS)
    node.step([], 10.5)
    assert node.alive == set(IDS)  # past token_confirm_s, but settling (peer_silent_s)
    node.step([*tokens(), *commands(0, (0.5, 0.0), 10.6)[:2]], 10.6)
    assert node.k == 1 and node.robots.held_k.tolist() == [0] * len(IDS) and not node.resumed


def test_after_its_own_stall_a_token_that_stays_gone_is_let_go_once_settled() -> None:
    """Settled (peer_silent_s) before the tick's fresh wait ends (step_timeout_s): the agent is gone, yet the tick
    it was waited for at waits for it to the end (its token may still be on its way back), then holds it."""
    tm = replace(T, step_timeout_s=5.0)
    node = started(timing=tm)
    node.step([], 0.0)
    node.step(tokens(IDS[:1], up=False), 5.0)  # stalled 5 s; agent IDS[0]'s token goes
    advance(node, 5.0, 5.0 + tm.peer_silent_s - 0.5, inputs=commands(0, (0.5, 0.0), 5.0, skip=(IDS[0],)))
    assert IDS[0] in node.alive  # kept while the sessions settle (peer_silent_s)
    advance(node, 5.0 + tm.peer_silent_s - 0.5, 5.0 + tm.step_timeout_s - 0.5)
    assert IDS[0] not in node.alive and node.k == 0 and node.missing() == [IDS[0]]
    out = advance(node, 5.0 + tm.step_timeout_s - 0.5, 5.0 + tm.step_timeout_s + 0.5)
    assert node.k == 1 and node.strikes == {IDS[0]: 1}
    assert [t.clock.alive for t in ticks(out)][-1] == tuple(sorted(IDS[1:]))


def test_while_its_own_router_link_is_gone_the_world_holds_and_nobody_is_lost() -> None:
    """Lockstep: the router dies while tick 0 waits (every token goes with it). No step times out, no robot is
    stepped uncommanded, nobody is lost; once back, tick 0 goes out again and the run goes on."""
    node = started()
    node.step([], 0.0)
    node.step(commands(0, (1.0, 0.0), 0.1, skip=tuple(IDS[2:])), 0.1)
    out = advance(node, 0.1, 0.1 + 4 * T.step_timeout_s, inputs=[RouterReach(False), *tokens(up=False)])
    assert out == [] and node.k == 0 and node.phase == Phase.NO_AGENTS and node.alive == set(IDS)
    now = 0.1 + 4 * T.step_timeout_s
    assert [t.clock.k for t in ticks(node.step([RouterReach(True), *tokens()], now))] == [0]
    node.step(commands(0, (1.0, 0.0), now + 0.1, skip=tuple(IDS[:2])), now + 0.1)  # (the first two were kept)
    assert node.k == 1 and node.uncommanded_k == -1 and node.strikes == {}


def test_a_realtime_world_moves_its_schedule_on_by_the_time_its_link_was_gone() -> None:
    node = started(ClockMode.REALTIME, now=100.0)
    period = S.meta.dt_s / 10.0
    node.step([], 100.0)  # tick 0, due at 100 + period
    assert node.step([RouterReach(False)], 100.001) == [] and node.phase == Phase.NO_AGENTS
    assert advance(node, 100.001, 101.901) == []  # (stepped as the runtime does: not a stall of its own)
    assert [t.clock.k for t in ticks(node.step([RouterReach(True)], 102.001))] == [0]
    assert node.wake_at_s() == pytest.approx(102.0 + period)


# ---------------------------------------------------------------------------------------- the end


def test_end_of_duration() -> None:
    node = started()
    node.n_ticks = 1
    node.step([], 0.0)
    node.step(commands(0, (0.0, 0.0), 0.0), 0.0)
    out = node.step([], 0.0)
    assert ended(out) == "duration"
    (tick,) = ticks(out)
    assert tick.clock.end and tick.clock.reason == "duration" and "world_overruns" in tick.clock.stats


def test_stop_ends_the_mission_at_once_and_done_stays_done() -> None:
    node = started()
    out = node.step([Stop()], 0.0)
    assert ended(out) == "stopped" and ticks(out)[0].clock.end
    assert node.step([], 1.0) == [Exit(0, "stopped")]
    waiting = started()
    waiting.step([], 0.0)  # tick 0 waits for its commands
    assert waiting.step([Stop()], 0.1) == [] and waiting.k == 1  # the wait ends now: robots held
    out = waiting.step([], 0.1)
    assert ended(out) == "stopped" and ticks(out)[0].clock.k == 1


def test_converged_ends_the_mission() -> None:
    node = started()
    node.robots.p = np.asarray(S.target_m) + S.offsets
    out = node.step([], 0.0)
    assert ended(out) == "converged" and ticks(out)[0].clock.reason == "converged"


# ---------------------------------------------------------------------------------------- realtime


def test_realtime_advances_on_wall_time_and_counts() -> None:
    node = started(ClockMode.REALTIME, now=100.0)
    period = S.meta.dt_s / 10.0
    out = node.step([], 100.0)
    assert ticks(out)[0].clock.mode == ClockMode.REALTIME and node.wake_at_s() == pytest.approx(100.0 + period)
    assert node.awaiting(100.0) is None  # only the due time moves it on
    # latency: from the step that published the tick (100.0) to each command's arrival (100.002)
    assert node.step(commands(0, (0.1, 0.0), 100.002, skip=(IDS[0],)), 100.003) == [] and node.k == 0
    node.step([], 100.0 + period)
    assert node.k == 1 and node.missed == 1 and node.expected == len(IDS)
    node.step([], 100.0 + 5 * period)  # tick 1 goes out late
    assert node.overruns == 1
    stats = node.stats()
    assert stats["latency_samples"] == len(IDS) - 1 and stats["latency_p50_ms"] == pytest.approx(2.0)
    assert stats["missed_deadlines"] == 1
    node.step([], 100.0 + 6 * period)
    assert node.k == 2


# ------------------------------------------------------------------------------------------ sensing


def test_a_robot_next_to_an_obstacle_gets_its_contour() -> None:
    node = started()
    ob = S.obstacles[0]
    vx, vy = ob.vertices_m[0]
    node.robots.p[0] = (vx - 1.0, vy - 1.0)
    (tick,) = ticks(node.step([], 0.0))
    mine = [m.scan for m in tick.states if m.id == IDS[0] and m.scan is not None]
    assert len(mine) == 1 and mine[0].id == IDS[0] and mine[0].k == tick.clock.k and len(mine[0].points) > 0
    assert all(o == ob.id or o in {x.id for x in S.obstacles} for _, _, o in mine[0].points)
    near = min(np.hypot(x - (vx - 1.0), y - (vy - 1.0)) for x, y, _ in mine[0].points)
    assert near <= np.sqrt(2.0) + 1e-9  # the vertex itself is within sqrt(2) m
    assert max(np.hypot(x - (vx - 1.0), y - (vy - 1.0)) for x, y, _ in mine[0].points) <= S.planner.sensing_range_m


def test_a_held_robot_is_in_the_scans_of_the_agents_near_it_and_only_theirs() -> None:
    """An agent gone: its robot is held, and the world's range sensing reports it to the agents within
    body_range_m (with cells they may never have heard its beacons), as (id, head point)."""
    node = started()
    reach = node.robots.body_range_m
    gone, near, far = IDS[0], IDS[1], IDS[2]
    node.robots.p[:] = [(0.0, 1e4 + 100.0 * i) for i in range(len(IDS))]  # everyone far apart, no obstacle near
    node.robots.p[0] = (5000.0, 5000.0)
    node.robots.p[1] = (5000.0 + reach - 1.0, 5000.0)  # just inside
    node.robots.p[2] = (5000.0, 5000.0 + reach + 1.0)  # just outside
    node.step(tokens([gone], up=False), 0.0)
    (tick,) = ticks(node.step([], 0.5))  # tick 0 again, its token's going confirmed
    scans = {m.id: m.scan for m in tick.states if m.scan is not None}  # (each scan rides in its state)
    assert scans[near].bodies == ((gone, 5000.0, 5000.0),) and scans[near].points == ()
    assert far not in scans and gone not in scans  # nothing in range; the gone agent gets no scan
    (tick,) = ticks(node.step(tokens([gone]), 1.0))  # back (a restarted agent): nobody's body any more
    assert all(m.scan is None for m in tick.states)
