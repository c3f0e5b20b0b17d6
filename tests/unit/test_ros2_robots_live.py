"""ROS 2 mode's plant (simworld/ros2_io.ros2_world) against the unicycle's equations, the live view's
knowledge scene, and the launcher's optional `--foxglove` value. No zenoh."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from foxglove.messages import SceneUpdate
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from monitor.live import knowledge_update
from monitor.scene import GROUP_RGB
from reconswarm.net.node import Role, Token
from reconswarm.net.wire import wire
from reconswarm.net.wire.wire import ClockMode
from reconswarm.scenario.model import load
from reconswarm_bringup.cli_launch import FOXGLOVE_PORT, optional_values
from simworld.ros2_io import Ros2Robots, ros2_world
from simworld.world import Command, WorldNode
from tests.support import PAPER


def _started(world: WorldNode) -> float:
    now = 100.0
    world.step([*(Token(Role.AGENT, True, a) for a in world.ids), Token(Role.MONITOR, True)], now)
    assert world.started  # the readiness barrier passed
    return now


def _base(world: WorldNode) -> Ros2Robots:
    assert isinstance(world.robots, Ros2Robots)  # (ROS 2 mode's plant: a robot base)
    return world.robots


def _twist(agent_id: int, v: float, w: float, at_s: float, k: int = 0) -> Command:
    """A cmd_vel as the port hands it over: of the tick it dates it to (simworld/ros2_io.planned_tick)."""
    return Command(wire.Cmd(agent_id, k, v, w), at_s)


def _states(out: list) -> list[wire.State]:
    return [m for m in out if isinstance(m, wire.State)]


def test_twist_is_held_over_the_step_on_the_exact_arc():
    s = load(PAPER)
    world = ros2_world(s, speed=10.0)
    assert world.clock == ClockMode.REALTIME
    now = _started(world)
    dt, l_m = s.meta.dt_s, s.head_offsets
    out = world.step([], now)  # publishes tick 0
    assert isinstance(out[0], wire.Clock) and out[0].k == 0
    s0 = np.array([[m.x, m.y] for m in _states(out)])
    th0 = np.array([m.theta for m in _states(out)])
    v, w = 3.0, 0.8
    # robot 3 only; the others get no command and stay put. The tick is due (a period is dt / speed = 5 ms):
    # apply and advance
    world.step([_twist(world.ids[2], v, w, now)], now + 0.01)
    out = world.step([], now + 0.01)  # publish tick 1
    s1 = np.array([[m.x, m.y] for m in _states(out)])
    th1 = np.array([m.theta for m in _states(out)])
    # eq. (1) with (v, ω) constant over dt: θ += ω dt; s moves by (v/ω)(sin θ1 - sin θ0, cos θ0 - cos θ1)
    exp_x = s0[2, 0] + v / w * (math.sin(th0[2] + w * dt) - math.sin(th0[2]))
    exp_y = s0[2, 1] + v / w * (math.cos(th0[2]) - math.cos(th0[2] + w * dt))
    assert math.hypot(s1[2, 0] - exp_x, s1[2, 1] - exp_y) < 1e-12
    assert abs(math.remainder(th1[2] - th0[2] - w * dt, 2 * math.pi)) < 1e-12
    others = [i for i in range(len(world.ids)) if i != 2]
    assert np.array_equal(s1[others], s0[others]) and np.array_equal(th1[others], th0[others])
    assert tuple(_base(world).vw[2]) == (v, w) and not _base(world).vw[others].any()
    # the head point is the body point plus l [cos θ, sin θ]
    p1 = np.array([[m.px, m.py] for m in _states(out)])
    assert np.allclose(p1 - s1, l_m[:, None] * np.stack([np.cos(th1), np.sin(th1)], axis=1), atol=1e-12)


def test_a_robot_without_cmd_vel_for_hold_time_stops():
    s = load(PAPER)
    world = ros2_world(s, speed=10.0)
    now = _started(world)
    world.step([], now)
    world.step([_twist(world.ids[0], 2.0, 0.0, now)], now)
    hold_ticks = round(world.timing.hold_sim_s / s.meta.dt_s)
    moving = []
    for _ in range(hold_ticks + 3):
        now += 0.01
        world.step([], now)  # apply tick k
        world.step([], now)  # publish tick k + 1
        moving.append(bool(_base(world).vw[0, 0]))
    assert moving == [True] * (hold_ticks + 1) + [False] * 2  # held for hold_sim_s, then stopped


def test_twist_from_an_unknown_robot_is_refused():
    world = ros2_world(load(PAPER), speed=10.0)
    now = _started(world)
    world.step([_twist(99, 1.0, 0.0, now)], now)
    assert world.rejected == 1 and not world.robots.cmds


def _decoded(msg: SceneUpdate) -> Any:
    """The message as a reader decodes it: protobuf, with the schema the SDK publishes."""
    schema = SceneUpdate.get_schema()
    pool = descriptor_pool.DescriptorPool()
    for f in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name)).FromString(msg.encode())


def test_knowledge_scene_has_every_agents_hulls_in_its_group_colour():
    tri = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]])
    sq = np.array([[10.0, 10.0], [12.0, 10.0], [12.0, 12.0], [10.0, 12.0]])
    upd = _decoded(knowledge_update({2: {"a": tri, "b": sq}, 5: {"a": tri}, 7: {}}, {2: 1, 5: 0},
                                    1_700_000_000_123_456_789))
    ents = {e.id: e for e in upd.entities}
    assert set(ents) == {"knowledge/2", "knowledge/5", "knowledge/7"}
    assert [[[p.x, p.y] for p in ln.points] for ln in ents["knowledge/2"].lines] == [tri.tolist(), sq.tolist()]
    assert all(ln.type == 1 for ln in ents["knowledge/2"].lines)  # foxglove.LinePrimitive.Type LINE_LOOP
    c2, c5 = ents["knowledge/2"].lines[0].color, ents["knowledge/5"].lines[0].color
    assert (c2.r, c2.g, c2.b) == pytest.approx(GROUP_RGB[1]) and (c5.r, c5.g, c5.b) == pytest.approx(GROUP_RGB[0])
    assert len(ents["knowledge/7"].lines) == 0
    assert (upd.entities[0].timestamp.seconds, upd.entities[0].timestamp.nanos) == (1_700_000_000, 123_456_789)
    assert len(upd.deletions) == 1  # each update replaces the previous one


@pytest.mark.parametrize(("argv", "expected"), [
    (["--foxglove"], ["--foxglove", str(FOXGLOVE_PORT)]),
    (["--foxglove", "-n", "3"], ["--foxglove", str(FOXGLOVE_PORT), "-n", "3"]),
    (["--foxglove", "9000", "-n", "3"], ["--foxglove", "9000", "-n", "3"]),
    (["-n", "3"], ["-n", "3"]),
])
def test_foxglove_takes_an_optional_port(argv, expected):
    assert optional_values(argv) == expected
