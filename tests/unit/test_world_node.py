"""The world's tick logic (simworld/world.py) driven by hand: no zenoh, no processes, times given."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from reconswarm.errors import ProcessFailure
from reconswarm.net import wire
from reconswarm.net.keys import WireError
from reconswarm.net.timing import Timing
from reconswarm.net.wire import ClockMode
from reconswarm.plant import unicycle
from reconswarm.scenario.model import load
from simworld.world import Phase, Step, WorldNode
from tests.support import PAPER

T = Timing(start_timeout_s=10.0, republish_s=0.5, step_timeout_s=5.0, strikes=2, hold_sim_s=0.2, no_agents_grace_s=30.0)
S = load(PAPER)
IDS = [a.id for a in S.agents]


def up(node: WorldNode, ids: list[int] | None = None) -> None:
    for a in IDS if ids is None else ids:
        node.agent_up(a, True)
    node.monitor_up(True)


def started(clock: ClockMode = ClockMode.LOCKSTEP, now: float = 0.0) -> WorldNode:
    node = WorldNode(S, clock, 10.0, T)
    up(node)
    assert node.step(now).out == [] and node.started
    return node


def command_all(node: WorldNode, k: int, u: tuple[float, float], now: float, skip: tuple[int, ...] = ()) -> None:
    for a in IDS:
        if a not in skip:
            node.command(wire.Cmd(a, k, *u), now)


def advance(node: WorldNode, t0: float, t1: float, every_s: float = 0.5) -> Step:
    """Call step every every_s from t0 to t1 (as the adapter would, so the world never looks stalled itself);
    return the last step with every output in between."""
    outs = []
    t = t0
    while True:
        t = min(t1, t + every_s)
        st = node.step(t)
        outs += st.out
        if t >= t1 or st.ended:
            return Step(outs, st.wake_s, st.ended)


def test_barrier_waits_for_every_agent_and_the_monitor() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    up(node, IDS[:-1])
    node.monitor_up(False)
    st = node.step(0.0)
    assert st.out == [] and st.ended is None and st.wake_s == pytest.approx(10.0) and not node.started
    node.agent_up(IDS[-1], True)
    assert not node.step(1.0).out and not node.started  # the monitor is still missing
    node.monitor_up(True)
    node.step(2.0)
    assert node.started and node.phase == Phase.TICK


def test_barrier_times_out_naming_who_is_missing() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    up(node, IDS[1:])
    node.monitor_up(False)
    node.step(0.0)
    with pytest.raises(ProcessFailure, match=f"agent {IDS[0]}, monitor"):
        node.step(10.5)


def test_stopped_before_the_start() -> None:
    node = WorldNode(S, ClockMode.LOCKSTEP, 10.0, T)
    assert node.step(0.0, stopping=True).ended == "stopped" and not node.started


def test_lockstep_waits_for_every_command_then_integrates() -> None:
    node = started()
    st = node.step(0.0)
    (tick,) = st.out
    assert tick.clock.k == 0 and tick.clock.alive == tuple(sorted(IDS)) and not tick.clock.end
    assert [m.id for m in tick.states] == IDS and tick.truth.ids == tuple(IDS)
    assert all(m.scan.points for m in tick.states if m.scan is not None)
    p0, th0 = node.p.copy(), node.theta.copy()
    assert node.awaiting() == len(IDS)  # the adapter sleeps until every command could be in
    command_all(node, 0, (0.5, 0.2), 0.01, skip=(IDS[3],))
    assert node.step(0.02).out == [] and node.k == 0  # one command missing: no advance
    assert node.awaiting() == 1
    node.command(wire.Cmd(IDS[3], 0, 0.5, 0.2), 0.03)
    node.step(0.04)
    assert node.k == 1
    # the command is the unicycle's (v, ω) = (0.5 m/s, 0.2 rad/s); eq. 3 makes it the head point's velocity
    u = np.stack([0.5 * np.cos(th0) - S.head_offsets * 0.2 * np.sin(th0),
                  0.5 * np.sin(th0) + S.head_offsets * 0.2 * np.cos(th0)], axis=1)
    p1, th1 = unicycle.step(p0, th0, u, S.head_offsets, S.meta.dt_s, S.world.max_speed_mps,
                            S.world.max_turn_rate_radps)
    assert np.array_equal(node.p, p1) and np.array_equal(node.theta, th1)
    assert node.step(0.05).out[0].clock.k == 1


def test_a_waiting_tick_is_published_again_every_republish_s() -> None:
    node = started()
    node.step(0.0)
    assert node.step(0.4).out == []
    again = node.step(0.5).out
    assert [o.clock.k for o in again] == [0] and node.k == 0
    assert node.step(0.9).out == []
    assert [o.clock.k for o in node.step(1.0).out] == [0]


def test_a_silent_robot_is_held_then_stopped_and_strikes_out() -> None:
    node = started()
    silent = IDS[2]
    i = IDS.index(silent)
    now = 0.0
    node.step(now)
    command_all(node, 0, (1.0, 0.0), now)
    node.step(now)
    trail = [node.p[i].copy()]
    hold_ticks = round(T.hold_sim_s / S.meta.dt_s)
    for k in range(1, 3):
        node.step(now)  # publish tick k
        command_all(node, k, (1.0, 0.0), now, skip=(silent,))
        assert node.missing() == [silent]
        advance(node, now, now + T.step_timeout_s)  # the step times out: the robot is held
        now += T.step_timeout_s
        assert node.k == k + 1
        trail.append(node.p[i].copy())
    assert node.strikes[silent] == 2 and silent in node.unresponsive
    # Not waited for any more: the others' commands are enough.
    for k in range(3, 3 + hold_ticks + 2):
        node.step(now)
        command_all(node, k, (1.0, 0.0), now, skip=(silent,))
        node.step(now)
        assert node.k == k + 1
        trail.append(node.p[i].copy())
    moved = [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(trail)]
    assert all(m > 0 for m in moved[:hold_ticks])  # the last command is held for hold_sim_s
    assert all(m == 0 for m in moved[hold_ticks:])  # then the robot stops
    node.step(now)
    node.command(wire.Cmd(silent, node.k, 0.0, 0.0), now)
    assert silent not in node.unresponsive and silent not in node.strikes


def test_late_commands_count_as_the_latest() -> None:
    node = started()
    node.step(0.0)
    command_all(node, 0, (1.0, 0.0), 0.0, skip=(IDS[0],))
    advance(node, 0.0, 5.0)  # timed out without agent IDS[0]
    node.command(wire.Cmd(IDS[0], 0, 0.3, 0.0), 5.1)  # tick 0's command, late
    node.step(5.1)
    command_all(node, 1, (1.0, 0.0), 5.2, skip=(IDS[0],))
    advance(node, 5.2, 10.2)
    # held as the head point's velocity u = M(θ_0) [0.3, 0] at the heading of tick 0, the one it was planned at
    th0 = S.headings[0]
    assert node.held[0].tolist() == [0.3 * np.cos(th0), 0.3 * np.sin(th0)] and node.held_k[0] == 0


def test_unknown_agent_command_is_refused() -> None:
    node = started()
    with pytest.raises(WireError):
        node.command(wire.Cmd(999, 0, 0.0, 0.0), 0.0)
    node.agent_up(999, True)
    assert 999 not in node.alive


def test_no_agents_holds_then_ends_or_goes_on() -> None:
    node = started()
    for a in IDS:
        node.agent_up(a, False)
    st = node.step(0.0)
    assert st.out == [] and node.phase == Phase.NO_AGENTS and st.wake_s == pytest.approx(30.0)
    assert advance(node, 0.0, 10.0).out == []
    node.agent_up(IDS[0], True)
    assert [o.clock.k for o in node.step(10.5).out] == [0]  # back: the tick goes out
    node.agent_up(IDS[0], False)
    advance(node, 10.5, 16.0)  # nobody left to wait for: next tick
    assert node.k == 1 and node.phase == Phase.NO_AGENTS
    st = advance(node, 16.0, 46.5)
    assert st.ended == "no agents" and st.out[0].clock.end and st.out[0].clock.reason == "no agents"


def test_end_of_duration_and_stop() -> None:
    node = started()
    node.n_ticks = 1
    node.step(0.0)
    command_all(node, 0, (0.0, 0.0), 0.0)
    node.step(0.0)
    st = node.step(0.0)
    assert st.ended == "duration" and st.out[0].clock.end and "world_overruns" in st.out[0].clock.stats
    node2 = started()
    st2 = node2.step(0.0, stopping=True)
    assert st2.ended == "stopped"
    assert node2.step(1.0).ended == "stopped"  # done stays done


def test_converged_ends_the_mission() -> None:
    node = started()
    node.p = np.asarray(S.target_m) + S.offsets
    st = node.step(0.0)
    assert st.ended == "converged" and st.out[0].clock.reason == "converged"


def test_realtime_advances_on_wall_time_and_counts() -> None:
    node = started(ClockMode.REALTIME, now=100.0)
    period = S.meta.dt_s / 10.0
    st = node.step(100.0)
    assert st.out[0].clock.mode == ClockMode.REALTIME and st.wake_s == pytest.approx(100.0 + period)
    node.sent(0, 100.0)
    command_all(node, 0, (0.1, 0.0), 100.002, skip=(IDS[0],))
    assert node.step(100.001).out == [] and node.k == 0
    node.step(100.0 + period)
    assert node.k == 1 and node.missed == 1 and node.expected == len(IDS)
    node.step(100.0 + 5 * period)  # tick 1 goes out late
    assert node.overruns == 1
    stats = node.stats()
    assert stats["latency_samples"] == len(IDS) - 1 and stats["latency_p50_ms"] == pytest.approx(2.0)
    assert stats["missed_deadlines"] == 1
    node.step(100.0 + 6 * period)
    assert node.k == 2


def test_a_robot_next_to_an_obstacle_gets_its_contour() -> None:
    node = started()
    ob = S.obstacles[0]
    vx, vy = ob.vertices_m[0]
    node.p[0] = (vx - 1.0, vy - 1.0)
    (tick,) = node.step(0.0).out
    mine = [m.scan for m in tick.states if m.id == IDS[0] and m.scan is not None]
    assert len(mine) == 1 and mine[0].id == IDS[0] and mine[0].k == tick.clock.k and len(mine[0].points) > 0
    assert all(o == ob.id or o in {x.id for x in S.obstacles} for _, _, o in mine[0].points)
    near = min(np.hypot(x - (vx - 1.0), y - (vy - 1.0)) for x, y, _ in mine[0].points)
    assert near <= np.sqrt(2.0) + 1e-9  # the vertex itself is within sqrt(2) m
    assert max(np.hypot(x - (vx - 1.0), y - (vy - 1.0)) for x, y, _ in mine[0].points) <= S.planner.sensing_range_m


def test_a_world_stalled_itself_waits_afresh_and_stays_in_lockstep() -> None:
    """SIGSTOP of simworld: when it runs again, no step has timed out (nobody was late but the world), the
    tick goes out again at once, and it waits for every agent even while their tokens flap."""
    node = started()
    node.step(0.0)
    command_all(node, 0, (0.5, 0.0), 0.0, skip=(IDS[0], IDS[1]))
    for a in IDS:  # the world's own session reconnects: every token seems gone for a moment
        node.agent_up(a, False)
    st = node.step(10.0)  # 10 s later
    assert [o.clock.k for o in st.out] == [0] and node.k == 0 and not node.strikes
    assert node.missing() == [IDS[0], IDS[1]]
    for a in IDS:
        node.agent_up(a, True)
    node.command(wire.Cmd(IDS[0], 0, 0.5, 0.0), 10.1)
    node.command(wire.Cmd(IDS[1], 0, 0.5, 0.0), 10.1)
    node.step(10.2)
    assert node.k == 1 and node.held_k.tolist() == [0] * len(IDS) and not node.resumed


def test_a_held_robot_is_in_the_scans_of_the_agents_near_it_and_only_theirs() -> None:
    """An agent gone: its robot is held, and the world's range sensing reports it to the agents within
    body_range_m (with cells they may never have heard its beacons), as (id, head point)."""
    node = started()
    gone, near, far = IDS[0], IDS[1], IDS[2]
    node.p[:] = [(0.0, 1e4 + 100.0 * i) for i in range(len(IDS))]  # everyone far apart, no obstacle near
    node.p[0] = (5000.0, 5000.0)
    node.p[1] = (5000.0 + node.body_range_m - 1.0, 5000.0)  # just inside
    node.p[2] = (5000.0, 5000.0 + node.body_range_m + 1.0)  # just outside
    node.agent_up(gone, False)
    (tick,) = node.step(0.0).out
    scans = {m.id: m.scan for m in tick.states if m.scan is not None}  # (each scan rides in its state)
    assert scans[near].bodies == ((gone, 5000.0, 5000.0),) and scans[near].points == ()
    assert far not in scans and gone not in scans  # nothing in range; the gone agent gets no scan
    node.agent_up(gone, True)  # back (a restarted agent): its robot is nobody's body any more
    assert all(not b for b in node.held_bodies())
