"""ROS 2 mode (`--ros2`) for the world: the robots' motion interface as ROS 2 topics over Zenoh.

Per robot i the plant publishes `/robot_<i>/odom` (nav_msgs/Odometry: body pose s_i, θ_i in frame `odom`,
child frame `robot_<i>/base_link`, stamp = simulated time, twist = the (v, ω) it moved with) instead of
its state key, and takes `/robot_<i>/cmd_vel` (geometry_msgs/Twist: linear.x = v, angular.z = ω) instead
of the command key, as node `simworld` with rmw_zenoh's keys, attachments and liveliness tokens
(reconswarm/net/ros2_node.py). Scans, clock and truth stay on the project's keys.

`Ros2World` is the world's state machine (simworld/world.py) with the plant a robot base is: it holds the
latest (v, ω) of each robot (a Twist carries no tick: it counts for the tick in progress when it
arrives) and moves the body on the exact arc (`unicycle.step_vw`, saturated to the scenario's limits).
ROS 2 topics carry no tick, so ROS 2 mode is realtime only.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from reconswarm.net import ros2, wire
from reconswarm.net.keys import WireError
from reconswarm.net.ros2_node import Ros2Node
from reconswarm.net.wire import ClockMode
from reconswarm.plant import unicycle
from reconswarm.scenario.model import Scenario
from simworld.world import WorldNode


class Ros2World(WorldNode):
    """The world whose plant is a robot base: the (v, ω) of a cmd_vel (`twist`) moves the body on its arc."""

    def __init__(self, s: Scenario, speed: float, **kw: Any) -> None:
        super().__init__(s, ClockMode.REALTIME, speed, **kw)
        self.vw = np.zeros((len(self.ids), 2))  # (v, ω) each robot moved with over the last step

    def twist(self, agent_id: int, v_mps: float, omega_radps: float, now_s: float) -> None:
        """A cmd_vel of robot `agent_id`: held from the tick in progress on."""
        if agent_id not in self.index:
            raise WireError(f"agent {agent_id} is not in the scenario")
        self.cmds.setdefault(self.k, {})[self.index[agent_id]] = np.array([v_mps, omega_radps])
        self.unresponsive.discard(agent_id)
        sent = self.pub_time.get(self.k)
        if sent is not None:
            self.latency_ms.append((now_s - sent) * 1000.0)

    def plant_input(self, vw: np.ndarray, theta: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """A robot base holds its cmd_vel's (v, ω) itself (and moves on the arc: `integrate`)."""
        return vw

    def integrate(self, vw: np.ndarray) -> None:
        w = self.s.world
        self.p, self.theta, v, om = unicycle.step_vw(self.p, self.theta, vw[:, 0], vw[:, 1], self.l, self.s.meta.dt_s,
                                                     w.max_speed_mps, w.max_turn_rate_radps)
        self.vw = np.stack([v, om], axis=1)


class WorldRos2:
    """The node `simworld`: an odom publisher and a cmd_vel subscription per robot."""

    def __init__(self, session: Any, domain_id: int, world: Ros2World, callback: Any) -> None:
        """callback(sample): where cmd_vel samples go (the adapter's inbox)."""
        self.world = world
        self.node = Ros2Node(session, domain_id, "simworld")
        self.odom = {a: self.node.publisher(ros2.odom_topic(a), ros2.ODOMETRY) for a in world.ids}
        for a in world.ids:
            self.node.subscription(ros2.cmd_vel_topic(a), ros2.TWIST, callback)
        self.agent_of = {ros2.cmd_vel_key(domain_id, a): a for a in world.ids}
        self.odom_out = self.cmd_in = self.counted = 0

    def owns(self, key: str) -> bool:
        return key in self.agent_of

    def decode(self, key: str, payload: bytes) -> wire.Cmd:
        """A cmd_vel sample as robot i's command for the tick in progress (Ros2Error when it must be dropped);
        the adapter admits it (bounded, from agent i's session) before `command` applies it."""
        v, om = ros2.twist_from_ros(payload)
        return wire.Cmd(self.agent_of[key], self.world.k, v, om)

    def command(self, c: wire.Cmd, now_s: float) -> None:
        """An admitted cmd_vel into the world."""
        self.world.twist(c.id, c.v_mps, c.omega_radps, now_s)
        self.cmd_in += 1

    def publish(self, states: list[wire.State]) -> None:
        """Each robot's state at this tick as its odometry (body pose; twist = the last step's (v, ω))."""
        for m in states:
            v, om = self.world.vw[self.world.index[m.id]]
            self.odom[m.id].put(ros2.odom_to_ros(ros2.Odom(m.id, m.t, m.x, m.y, m.theta, float(v), float(om))))
            self.odom_out += 1

    def new_bad_attachments(self) -> int:
        n, self.counted = self.node.bad_attachments - self.counted, self.node.bad_attachments
        return n

    def close(self) -> None:
        self.node.close()
