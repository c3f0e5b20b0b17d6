"""ROS 2 mode's dating of a cmd_vel (a Twist has no tick): the plant takes it as planned from the oldest odometry it
published within `ros2_plan_age_periods` before the cmd_vel was sent (simworld/ros2_io.planned_tick), and an agent
sends none planned from an older one (agent/ros2_io.py, `AgentRos2.send`). The pure rule against its definition, then
both ends on real zenoh sessions (127.0.0.1), with the times carried in rmw_zenoh's attachments."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import zenoh
from hypothesis import given
from hypothesis import strategies as st

from agent.ros2_io import KEEP_TICKS, AgentRos2, Odometry
from reconswarm.net.node import Invalid
from reconswarm.net.ros2 import ros2
from reconswarm.net.ros2.ros2_node import Ros2Publisher, SentTimes
from reconswarm.net.runtime.inbox import Inbox
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.plant import unicycle
from reconswarm.scenario.model import load
from simworld.process import WorldAdapter, robot_io
from simworld.ros2_io import Ros2IO, Ros2Robots, planned_tick, ros2_world
from simworld.world import Command
from tests.support import PAPER, free_port, wait_subscribed, wait_until
from tests.unit.test_agent_host_sessions import two_sessions

MS = 1_000_000  # ns
S = load(PAPER)
PERIOD_S = S.meta.dt_s  # --speed 1


def test_the_oldest_tick_published_within_the_plan_age_before_the_cmd_vel_was_sent() -> None:
    out = {10: 1000 * MS, 11: 1050 * MS, 12: 1100 * MS}  # one odometry burst a period (50 ms)
    assert planned_tick(out, 1103 * MS, 50 * MS) == 12  # 3 ms after tick 12's: planned from it
    assert planned_tick(out, 1149 * MS, 50 * MS) == 12
    assert planned_tick(out, 1100 * MS, 50 * MS) == 11  # (sent with tick 12's: tick 11's was 50 ms before)
    assert planned_tick(out, 1020 * MS, 50 * MS) == 10  # (the agent's clock behind the plant's: the oldest)
    assert planned_tick({10: 1000 * MS, 11: 1200 * MS}, 1210 * MS, 50 * MS) == 11  # the plant behind its schedule
    with pytest.raises(ros2.Ros2Error, match=r"over 50\.0 ms after .*\(1\.0 ms more after the newest\).*clocks apart"):
        planned_tick(out, 1151 * MS, 50 * MS)  # later than any odometry an agent may plan from
    with pytest.raises(ros2.Ros2Error):
        planned_tick({}, 1000 * MS, 50 * MS)


@given(gaps=st.lists(st.integers(1, 200), min_size=1, max_size=12), age=st.integers(1, 100),
       basis=st.integers(0, 12), after=st.integers(0, 100))
def test_the_tick_given_is_never_later_than_the_one_planned_from_and_one_before_at_most(
        gaps: list[int], age: int, basis: int, after: int) -> None:
    """An agent planned from tick `basis` and sent `after` ms later, within the plan age: the plant dates its command
    to that tick or an older one (its hold rules then judge from where the robot stood then or before), and to the
    tick before at the oldest while the odometries come at least the plan age apart (the plant never ahead of its
    schedule, the plan age one period)."""
    at = [0]
    for g in gaps:
        at.append(at[-1] + g)
    published = {k: t * MS for k, t in enumerate(at)}
    basis = min(basis, len(at) - 1)
    after = min(after, age)
    got = planned_tick(published, (at[basis] + after) * MS, age * MS)
    assert got <= basis
    if all(g >= age for g in gaps):
        assert got >= basis - 1


def test_sent_times_are_taken_once_in_the_order_they_came_for_equal_bytes() -> None:
    sent = SentTimes()
    sent.note(b"twist", 1)
    sent.note(b"twist", 2)
    sent.note(b"other", 3)
    assert [sent.take(b"twist"), sent.take(b"twist"), sent.take(b"twist"), sent.take(b"other")] == [1, 2, None, 3]


def _wait(what: Any, n: int) -> list[Any]:
    got: list[Any] = []
    def more() -> bool:
        got.extend(what())
        return len(got) >= n

    wait_until(more, 10.0, f"{n} samples", every_s=0.02)
    assert len(got) == n
    return got


def test_the_plant_dates_a_cmd_vel_by_its_attachments_source_timestamp() -> None:
    with two_sessions() as (z, out):
        inbox = Inbox()
        world = Ros2IO(z, Keys("plan-age"), Gate(S, "simworld"), 0, Ros2Robots(S, 0.2), inbox.callback(), PERIOD_S)
        try:
            a = S.agents[0].id
            for k in range(4):  # ticks 0-3, a period apart
                world.publish(wire.State(a, k, k * PERIOD_S, 0.0, 0.0, 0.0, 0.5, 0.0))
                time.sleep(PERIOD_S)
            agent = Ros2Publisher(out, ros2.cmd_vel_key(0, a))
            twist = ros2.twist_to_ros(1.0, 0.0)
            wait_subscribed(out, agent.key)  # (the world's subscription reached the outside session)
            agent.put(twist, world.published_ns[1] + 2 * MS)  # planned from tick 1's odometry
            agent.put(twist, world.published_ns[3] + 5 * MS)  # from tick 3's (the same bytes, taken in order)
            agent.put(ros2.twist_to_ros(2.0, 0.0), world.published_ns[0] - 500 * MS)  # half a second before any
            agent.put(ros2.twist_to_ros(3.0, 0.0), world.published_ns[3] + 200 * MS)  # after what it can plan from
            got = _wait(lambda: inbox.take(1, 0.2), 4)
            dated: list[wire.Cmd | str] = []
            for _tag, (key, payload, *_rest) in got:
                try:
                    dated.append(world.dated(*world.twist(key, payload, 3)))
                except ros2.Ros2Error as exc:
                    dated.append(str(exc))
            assert dated[:3] == [wire.Cmd(a, 1, 1.0, 0.0), wire.Cmd(a, 3, 1.0, 0.0), wire.Cmd(a, 0, 2.0, 0.0)]
            assert "clocks apart" in str(dated[3])
            # A cmd_vel whose time was never noted (none is delivered so): older than any tick a command holds from.
            unnoted = world.twist(ros2.cmd_vel_key(0, a), ros2.twist_to_ros(0.5, -0.25), 3)
            assert unnoted == (wire.Cmd(a, 3, 0.5, -0.25), None)  # (as the gate judges it: of the newest tick)
            assert world.dated(*unnoted) == wire.Cmd(a, 3 - world.keep_ticks, 0.5, -0.25)
            # A stop sent after any odometry it may be planned from (an agent behind the clock, its hold over): stale,
            # which moves nothing but tells the world the agent is alive; any other Twist so late is refused.
            late = world.published_ns[3] + 200 * MS
            assert world.dated(wire.Cmd(a, 3, 0.0, 0.0), late) == wire.Cmd(a, 3 - world.keep_ticks, 0.0, 0.0)
            with pytest.raises(ros2.Ros2Error, match="clocks apart"):
                world.dated(wire.Cmd(a, 3, 0.0, 0.01), late)
            assert world.dated(wire.Cmd(a, 3, 0.0, 0.0), world.published_ns[2] + MS) == wire.Cmd(a, 2, 0.0, 0.0)
            world.ros2_node.bad_attachments = 2
            assert (len(world.dropped()), world.dropped()) == (2, [])
        finally:
            world.close()


def test_the_plant_publishes_each_robots_odometry_and_keeps_when_each_tick_was_out() -> None:
    limited = dataclasses.replace(S, world=dataclasses.replace(S.world, max_speed_mps=1.0, max_turn_rate_radps=0.5))
    with two_sessions() as (z, out):
        base = Ros2Robots(limited, 0.2)
        world = Ros2IO(z, Keys("plan-age"), Gate(S, "simworld"), 0, base, lambda _sample: None, PERIOD_S)
        a, i = S.agents[1].id, 1
        heard: list[Any] = []
        sub = out.declare_subscriber(ros2.odom_key(0, a), heard.append)
        try:
            wait_subscribed(z, ros2.odom_key(0, a))  # (the outside session's subscription reached the world's)
            base.integrate(base.vw + [[3.0, 2.0]] * len(base.ids))  # (v, ω) beyond the world's limits: saturated
            assert tuple(base.vw[i]) == (1.0, 0.5)
            before = time.time_ns()
            world.publish(wire.State(a, 7, 0.375, 4.0, -5.0, 0.25, 4.5, -5.0))
            assert before <= world.published_ns[7] <= time.time_ns()
            [sample] = _wait(lambda: [heard.pop(0)] if heard else [], 1)
            assert ros2.odom_from_ros(sample.payload.to_bytes(), a) == ros2.Odom(a, 0.375, 4.0, -5.0, 0.25, 1.0, 0.5)
            for k in range(8, 8 + 2 * world.keep_ticks):
                world.publish(wire.State(a, k, k * PERIOD_S, 0.0, 0.0, 0.0, 0.5, 0.0))
            newest = 8 + 2 * world.keep_ticks - 1
            assert sorted(world.published_ns) == list(range(newest - world.keep_ticks + 1, newest + 1))
            assert world.keep_ticks > base.hold_ticks + 1  # (past the plant's poses: a command dated so is stale)
        finally:
            sub.undeclare()
            world.close()


def test_the_world_admits_a_cmd_vel_before_it_dates_it_so_a_forgers_timestamp_is_an_impersonation() -> None:
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())
    port = WorldAdapter(ros2_world(S, speed=1.0), "plan-age", z, robot_io(0))
    try:
        assert isinstance(port.io, Ros2IO)
        a = S.agents[0].id
        port.io.publish(wire.State(a, 0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0))
        port.gate.world_k = 0  # (tick 0 out, as its clock says)
        key, genuine, forged = ros2.cmd_vel_key(0, a), ros2.twist_to_ros(1.0, 0.0), ros2.twist_to_ros(2.0, 0.0)
        port.io.ros2_node.sent.note(genuine, port.io.published_ns[0] + MS)
        assert port.decode(key, genuine, "PUT", "agent-session", 0.0) == Command(wire.Cmd(a, 0, 1.0, 0.0), 0.0)
        port.io.ros2_node.sent.note(forged, port.io.published_ns[0] + 10**12)  # "sent" 1000 s on: no odometry so old
        assert port.decode(key, forged, "PUT", "forger", 0.0) is None
        assert port.gate.count == 1 and set(port.gate.tally.rows) == {("impersonation", "forger")}
        assert port.rej.count == 0
        port.io.ros2_node.sent.note(forged, port.io.published_ns[0] + 10**12)  # from the agent's own session: invalid
        got = port.decode(key, forged, "PUT", "agent-session", 0.0)
        assert isinstance(got, Invalid) and "clocks apart" in got.reason and port.rej.count == 1
    finally:
        port.close()
        z.close()


def test_an_agent_sends_no_command_planned_from_odometry_older_than_a_period() -> None:
    with two_sessions() as (z, out):
        samples: list[Any] = []
        a = S.agents[0].id
        agent = AgentRos2(z, 0, a, 0.5, S.meta.dt_s, samples.append)
        cmd_vels: list[Any] = []
        sub = out.declare_subscriber(ros2.cmd_vel_key(0, a), cmd_vels.append)
        try:
            plant = Ros2Publisher(out, ros2.odom_key(0, a))
            wait_subscribed(out, plant.key)  # (each side's subscription reached the other)
            wait_subscribed(z, ros2.cmd_vel_key(0, a))
            now = time.time_ns()
            plant.put(ros2.odom_to_ros(ros2.Odom(a, 5 * S.meta.dt_s, 0.0, 0.0, 0.0, 0.0, 0.0)), now - 10_000 * MS)
            plant.put(ros2.odom_to_ros(ros2.Odom(a, 6 * S.meta.dt_s, 0.0, 0.0, 0.0, 0.0, 0.0)), now)
            got = _wait(lambda: [samples.pop(0)] if samples else [], 2)
            states = [agent.odometry(str(s.key_expr), s.payload.to_bytes()) for s in got]
            for o in states:
                assert not isinstance(o, Invalid)
                agent.keep(o)
            assert [o.state.k for o in states if not isinstance(o, Invalid)] == [5, 6]
            period_s = 2.0  # (--speed 0.025: room for this test's own delays)
            assert not agent.send(wire.Cmd(a, 5, 1.0, 0.0), period_s)  # its odometry 10 s old: a stop instead
            assert not agent.send(wire.Cmd(a, 7, 1.0, 0.0), period_s)  # no odometry of that tick (and a stop
            assert agent.send(wire.Cmd(a, 6, 1.0, 0.0), period_s)  # went out less than a hold ago: nothing)
            assert (agent.stale, agent.stops) == (2, 1)
            stop, sent = _wait(lambda: [cmd_vels.pop(0)] if cmd_vels else [], 2)
            assert ros2.twist_from_ros(stop.payload.to_bytes()) == (0.0, 0.0)
            stamp = ros2.unpack_attachment(sent.attachment.to_bytes()).source_timestamp_ns
            assert now <= stamp <= now + period_s * 1e9  # (what the plant dates it by: tick 6's, within a period)
            assert ros2.twist_from_ros(sent.payload.to_bytes()) == (1.0, 0.0)
        finally:
            sub.undeclare()
            agent.close()


@pytest.fixture
def agent() -> Iterator[AgentRos2]:
    """Agent 1's ROS 2 side on a session of its own (the tests note each odometry's time as its subscription
    would, `Ros2Node.sent`)."""
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())
    a = AgentRos2(z, 0, 1, 0.5, S.meta.dt_s, lambda _sample: None)
    try:
        yield a
    finally:
        a.close()
        z.close()


def odometry(agent: AgentRos2, k: int, sent_ns: int, x: float = 3.0, y: float = -2.0, theta: float = 0.7) -> bytes:
    """Agent 1's odometry of tick k as the plant publishes it, noted as published at sent_ns."""
    payload = ros2.odom_to_ros(ros2.Odom(1, k * S.meta.dt_s, x, y, theta, 0.0, 0.0))
    agent.ros2_node.sent.note(payload, sent_ns)
    return payload


def kept(agent: AgentRos2, payload: bytes) -> wire.State:
    """An odometry decoded and kept, as the agent's link keeps one its gate admitted."""
    o = agent.odometry(agent.odom_key, payload)
    assert isinstance(o, Odometry)
    agent.keep(o)
    return o.state


def test_an_odometry_is_the_state_of_its_tick_with_the_head_point_l_ahead_of_the_body(agent: AgentRos2) -> None:
    o = agent.odometry(agent.odom_key, odometry(agent, 7, 10**18))
    assert isinstance(o, Odometry) and o.sent_ns == 10**18
    m = o.state
    assert (m.id, m.k, m.t, m.x, m.y, m.theta) == (1, 7, 7 * S.meta.dt_s, 3.0, -2.0, 0.7)
    assert (m.px, m.py) == (3.0 + 0.5 * math.cos(0.7), -2.0 + 0.5 * math.sin(0.7))  # p = s + l [cos θ, sin θ]
    assert agent.published_ns == {}  # (decoded, not admitted: nothing is kept)
    agent.keep(o)
    assert agent.published_ns == {7: 10**18}
    other = ros2.odom_to_ros(ros2.Odom(2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))  # robot 2's frame on our topic
    bad = agent.odometry(agent.odom_key, other)
    assert isinstance(bad, Invalid) and bad.key == agent.odom_key and "of agent 2 on the topic of agent 1" in bad.reason
    assert agent.published_ns == {7: 10**18}
    agent.ros2_node.bad_attachments = 2
    assert agent.dropped() == [Invalid(agent.odom_key, "odometry without a valid rmw_zenoh attachment")] * 2
    assert agent.dropped() == []


def test_the_newest_odometries_times_are_kept(agent: AgentRos2) -> None:
    for k in range(KEEP_TICKS + 5):
        kept(agent, odometry(agent, k, 10**18 + k))
    assert sorted(agent.published_ns) == list(range(5, KEEP_TICKS + 5))


def test_a_command_goes_out_up_to_exactly_one_period_after_its_odometry_and_is_stamped_when_sent(
        agent: AgentRos2, caplog: pytest.LogCaptureFixture) -> None:
    t0, period_s = 10**18, 0.0125  # (--speed 4)
    stamps: list[int] = []  # (the source timestamp of each cmd_vel put)
    attach = agent.cmd_vel.publication.next_attachment

    def stamped(now_ns: int) -> bytes:
        stamps.append(now_ns)
        return attach(now_ns)

    agent.cmd_vel.publication.next_attachment = stamped  # type: ignore[method-assign]
    kept(agent, odometry(agent, 3, t0))
    agent.sent_ns = t0  # (a cmd_vel went out then: the plant holds it for 0.2 s of simulated time, 50 ms here)
    with caplog.at_level("WARNING"):
        assert not agent.send(wire.Cmd(1, 3, 1.0, 0.0), period_s, t0 + 12_500_001)
        assert not agent.send(wire.Cmd(1, 4, 1.0, 0.0), period_s, t0)  # no odometry of tick 4 (yet)
    assert (agent.stale, agent.stops) == (2, 0) and stamps == []
    said = [r.getMessage() for r in caplog.records]
    assert said == ["agent 1: a command not sent: planned from odometry published 12.5 ms ago, more than 12.5 ms "
                    "(the machine is behind the clock) [total 1; 0 stops sent instead]"]  # (then one every 5 s)
    assert agent.send(wire.Cmd(1, 3, 1.0, 0.0), period_s, t0 + 12_500_000)
    assert stamps == [t0 + 12_500_000] and agent.stale == 2  # (sent once, stamped when it was judged)


def test_an_agent_behind_the_clock_sends_a_stop_once_the_plants_hold_is_over_then_every_half_second(
        agent: AgentRos2) -> None:
    t0, period_s = 10**18, 0.0125  # (--speed 4: the hold, 0.2 s simulated, is 50 ms of wall time)
    sent: list[tuple[int | None, tuple[float, float]]] = []
    agent.cmd_vel.put = lambda payload, now_ns=None: sent.append(  # type: ignore[method-assign]
        (now_ns, ros2.twist_from_ros(payload)))
    kept(agent, odometry(agent, 3, t0))
    assert agent.send(wire.Cmd(1, 3, 0.8, 0.1), period_s, t0 + 5 * MS)  # a plan, in time
    late = [t0 + d * MS for d in (20, 54, 55, 70, 554, 555, 1055)]
    assert not any(agent.send(wire.Cmd(1, 3, 0.8, 0.1), period_s, at) for at in late)  # (odometry 20+ ms old)
    plan = agent.twist(wire.Cmd(1, 3, 0.8, 0.1))  # (the twist of that command: `test_..._exactly_u_dt`)
    assert sent == [(t0 + 5 * MS, plan), (t0 + 55 * MS, (0.0, 0.0)), (t0 + 555 * MS, (0.0, 0.0)),
                    (t0 + 1055 * MS, (0.0, 0.0))]
    kept(agent, odometry(agent, 4, t0 + 1100 * MS))
    assert agent.send(wire.Cmd(1, 4, 0.5, 0.0), period_s, t0 + 1101 * MS)  # in time again
    assert not agent.send(wire.Cmd(1, 4, 0.5, 0.0), period_s, t0 + 1150 * MS)  # (late, within the hold)
    assert agent.send(wire.Cmd(1, 4, 0.5, 0.0), period_s, t0 + 1105 * MS)
    assert not agent.send(wire.Cmd(1, 4, 0.5, 0.0), period_s, t0 + 1155 * MS)  # the hold over: a stop
    plan = agent.twist(wire.Cmd(1, 4, 0.5, 0.0))
    assert sent[4:] == [(t0 + 1101 * MS, plan), (t0 + 1105 * MS, plan), (t0 + 1155 * MS, (0.0, 0.0))]
    assert (agent.stale, agent.stops, agent.sent_ns) == (9, 4, t0 + 1155 * MS)



def test_the_twist_sent_moves_the_head_point_where_the_law_sends_it(agent: AgentRos2) -> None:
    """A robot base holds its twist over the step (the plant's exact arc, unicycle.step_vw): the agent sends the
    (v, ω) that takes the head point to p + u dt from the odometry the command was planned from, as the project's
    own plant moves it. The node's (v, ω) = M(θ)⁻¹ u held so would turn the robot by |u| dt / l: at the
    repulsion's 65 m/s beside a robot, 6.5 rad in a step, and the head point ends metres from where it was sent."""
    s = kept(agent, odometry(agent, 3, 10**18))  # θ = 0.7
    l_m, dt, th = np.array([0.5]), S.meta.dt_s, np.array([s.theta])
    p0 = np.array([[s.px, s.py]])
    off = []
    for u in ([[65.0 * math.cos(s.theta + math.pi / 2), 65.0 * math.sin(s.theta + math.pi / 2)]],  # across
              [[-30.0, 12.0]], [[1.5, -0.4]]):
        ua = np.array(u)
        v0, w0 = unicycle.inputs(ua, th, l_m)  # the node's command
        v, w = agent.twist(wire.Cmd(1, 3, float(v0[0]), float(w0[0])))
        p1 = unicycle.step_vw(p0, th, np.array([v]), np.array([w]), l_m, dt)[0]
        assert np.abs(p1 - (p0 + ua * dt)).max() < 1e-9
        held = unicycle.step_vw(p0, th, v0, w0, l_m, dt)[0]
        print(f"|u| {np.hypot(*ua[0]):.1f} m/s: the twist sent ends {np.hypot(*(p1 - p0 - ua * dt)[0]):.1e} m from "
              f"p + u dt, M(θ)⁻¹ u held {np.hypot(*(held - p0 - ua * dt)[0]):.3f} m")
        off.append(float(np.hypot(*(held - p0 - ua * dt)[0])))
    assert off[0] > 2.0 and off[1] > 0.5 and off[2] < 0.01  # (slow: the same to first order)
