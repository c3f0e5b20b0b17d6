"""ROS 2 mode's dating of a cmd_vel (a Twist has no tick): the plant takes it as planned from the oldest odometry it
published within `ros2_plan_age_periods` before the cmd_vel was sent (simworld/ros2_io.planned_tick), and an agent
sends none planned from an older one (agent/ros2_io.py, `AgentRos2.command`). The pure rule against its definition, then
both ends on real zenoh sessions (127.0.0.1), with the times carried in rmw_zenoh's attachments."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import zenoh
from hypothesis import given
from hypothesis import strategies as st

from agent.ros2_io import AgentRos2
from reconswarm.net import ros2, wire
from reconswarm.net.inbox import Inbox
from reconswarm.net.ros2_node import Ros2Publisher, SentTimes
from reconswarm.net.session import ZenohOptions
from reconswarm.scenario.model import load
from simworld.ros2_io import Ros2Plant, WorldRos2, planned_tick
from tests.support import PAPER, free_port

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
    with pytest.raises(ros2.Ros2Error, match="clocks apart"):  # later than any odometry an agent may plan from
        planned_tick(out, 1151 * MS, 50 * MS)
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


@contextmanager
def two_sessions() -> Iterator[tuple[Any, Any]]:
    port = free_port()
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{port}",), "peer").config())
    out = zenoh.open(ZenohOptions((f"tcp/127.0.0.1:{port}",), (), "peer").config())
    try:
        time.sleep(0.5)
        yield z, out
    finally:
        out.close()
        z.close()


def _wait(what: Any, n: int) -> list[Any]:
    got: list[Any] = []
    deadline = time.monotonic() + 10.0
    while len(got) < n and time.monotonic() < deadline:
        got += what()
        time.sleep(0.02)
    assert len(got) == n
    return got


def test_the_plant_dates_a_cmd_vel_by_its_attachments_source_timestamp() -> None:
    with two_sessions() as (z, out):
        inbox = Inbox()
        world = WorldRos2(z, 0, Ros2Plant(S, 0.2), inbox.callback, PERIOD_S)
        try:
            a = S.agents[0].id
            for k in range(4):  # ticks 0-3, a period apart
                world.publish(wire.State(a, k, k * PERIOD_S, 0.0, 0.0, 0.0, 0.5, 0.0))
                time.sleep(PERIOD_S)
            agent = Ros2Publisher(out, ros2.cmd_vel_key(0, a))
            twist = ros2.twist_to_ros(1.0, 0.0)
            time.sleep(0.3)
            agent.put(twist, world.published_ns[1] + 2 * MS)  # planned from tick 1's odometry
            agent.put(twist, world.published_ns[3] + 5 * MS)  # from tick 3's (the same bytes, taken in order)
            agent.put(ros2.twist_to_ros(2.0, 0.0), world.published_ns[0] - 500 * MS)  # half a second before any
            agent.put(ros2.twist_to_ros(3.0, 0.0), world.published_ns[3] + 200 * MS)  # after what it can plan from
            got = _wait(lambda: inbox.take(1, 0.2), 4)
            dated: list[int | str] = []
            for key, payload, *_rest in got:
                try:
                    dated.append(world.decode(key, payload, 3).k)
                except ros2.Ros2Error as exc:
                    dated.append(str(exc))
            assert dated[:3] == [1, 3, 0] and "clocks apart" in str(dated[3])
        finally:
            world.close()


def test_an_agent_sends_no_command_planned_from_odometry_older_than_a_period() -> None:
    with two_sessions() as (z, out):
        samples: list[Any] = []
        a = S.agents[0].id
        agent = AgentRos2(z, 0, a, 0.5, S.meta.dt_s, samples.append)
        cmd_vels: list[Any] = []
        sub = out.declare_subscriber(ros2.cmd_vel_key(0, a), cmd_vels.append)
        try:
            plant = Ros2Publisher(out, ros2.odom_key(0, a))
            time.sleep(0.3)
            now = time.time_ns()
            plant.put(ros2.odom_to_ros(ros2.Odom(a, 5 * S.meta.dt_s, 0.0, 0.0, 0.0, 0.0, 0.0)), now - 10_000 * MS)
            plant.put(ros2.odom_to_ros(ros2.Odom(a, 6 * S.meta.dt_s, 0.0, 0.0, 0.0, 0.0, 0.0)), now)
            got = _wait(lambda: [samples.pop(0)] if samples else [], 2)
            states = [agent.decode(str(s.key_expr), s.payload.to_bytes()) for s in got]
            assert [m.k if isinstance(m, wire.State) else m for m in states] == [5, 6]
            period_s = 2.0  # (--speed 0.025: room for this test's own delays)
            assert not agent.command(wire.Cmd(a, 5, 1.0, 0.0), period_s)  # its odometry 10 s old: not sent
            assert not agent.command(wire.Cmd(a, 7, 1.0, 0.0), period_s)  # no odometry of that tick
            assert agent.command(wire.Cmd(a, 6, 1.0, 0.0), period_s)
            assert agent.stale == 2 and agent.cmd_out == 1
            [sent] = _wait(lambda: [cmd_vels.pop(0)] if cmd_vels else [], 1)
            stamp = ros2.unpack_attachment(sent.attachment.to_bytes()).source_timestamp_ns
            assert now <= stamp <= now + period_s * 1e9  # (what the plant dates it by: tick 6's, within a period)
            assert ros2.twist_from_ros(sent.payload.to_bytes()) == (1.0, 0.0)
        finally:
            sub.undeclare()
            agent.close()
