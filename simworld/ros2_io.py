"""ROS 2 mode (`--ros2`) for the world: the robots' motion interface as ROS 2 topics over Zenoh.

Per robot i the plant publishes `/robot_<i>/odom` (nav_msgs/Odometry: body pose s_i, θ_i in frame `odom`,
child frame `robot_<i>/base_link`, stamp = simulated time, twist = the (v, ω) it moved with) instead of
its state key, and takes `/robot_<i>/cmd_vel` (geometry_msgs/Twist: linear.x = v, angular.z = ω) instead
of the command key, as node `simworld` with rmw_zenoh's keys, attachments and liveliness tokens
(reconswarm/net/ros2_node.py). Scans, clock and truth stay on the project's keys.

`Ros2World` is the world's state machine (simworld/world.py) with the plant a robot base is (`Ros2Plant`): it
holds the latest (v, ω) of each robot (a Twist carries no tick: it counts for the tick in progress when it
arrives) and moves the body on the exact arc (`unicycle.step_vw`, saturated to the scenario's limits).
ROS 2 topics carry no tick, so ROS 2 mode is realtime only. `WorldRos2` is the transport: the node
`simworld`'s odometry publishers and cmd_vel subscriptions (simworld/process.py's port uses it).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from reconswarm.net import ros2, wire
from reconswarm.net.ros2_node import Ros2Node
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.wire import ClockMode
from reconswarm.plant import unicycle
from reconswarm.scenario.model import Scenario
from simworld.plant import Plant
from simworld.world import WorldNode


class Ros2Plant(Plant):
    """The plant a robot base is: the (v, ω) of a cmd_vel is held as is and moves the body on its arc."""

    def __init__(self, s: Scenario, hold_sim_s: float) -> None:
        super().__init__(s, hold_sim_s)
        self.vw = np.zeros((len(self.ids), 2))  # (v, ω) each robot moved with over the last step

    def plant_input(self, vw: np.ndarray, theta: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """A robot base holds its cmd_vel's (v, ω) itself (and moves on the arc: `integrate`)."""
        return vw

    def integrate(self, vw: np.ndarray) -> None:
        w = self.s.world
        self.p, self.theta, v, om = unicycle.step_vw(self.p, self.theta, vw[:, 0], vw[:, 1], self.l, self.s.meta.dt_s,
                                                     w.max_speed_mps, w.max_turn_rate_radps)
        self.vw = np.stack([v, om], axis=1)


class Ros2World(WorldNode):
    """The world whose plant is a robot base: an admitted cmd_vel (a Command) holds from the tick in progress on."""

    def __init__(self, s: Scenario, speed: float, timing: Timing = TIMING) -> None:
        self.base = Ros2Plant(s, timing.hold_sim_s)
        super().__init__(s, ClockMode.REALTIME, speed, timing, self.base)

    def _command(self, c: wire.Cmd, at_s: float) -> None:
        """A cmd_vel of robot c.id (its tick is ignored: a Twist has none): held from the tick in progress on."""
        self.plant.command(c.id, self.k, c.v_mps, c.omega_radps)
        self.unresponsive.discard(c.id)
        sent = self.pub_time.get(self.k)
        if sent is not None:
            self.latency_ms.append((at_s - sent) * 1000.0)


class WorldRos2:
    """The node `simworld`: an odom publisher and a cmd_vel subscription per robot."""

    def __init__(self, session: Any, domain_id: int, base: Ros2Plant, callback: Any) -> None:
        """callback(sample): where cmd_vel samples go (the process's inbox)."""
        self.base = base
        self.node = Ros2Node(session, domain_id, "simworld")
        self.odom = {a: self.node.publisher(ros2.odom_topic(a), ros2.ODOMETRY) for a in base.ids}
        for a in base.ids:
            self.node.subscription(ros2.cmd_vel_topic(a), ros2.TWIST, callback)
        self.agent_of = {ros2.cmd_vel_key(domain_id, a): a for a in base.ids}
        self.counted = 0

    def owns(self, key: str) -> bool:
        return key in self.agent_of

    def decode(self, key: str, payload: bytes, k: int) -> wire.Cmd:
        """A cmd_vel sample as robot i's command for tick k, the newest published (Ros2Error when it must be
        dropped); the port admits it (bounded, from agent i's session) before the node holds it."""
        v, om = ros2.twist_from_ros(payload)
        return wire.Cmd(self.agent_of[key], k, v, om)

    def publish(self, m: wire.State) -> None:
        """A robot's state at this tick as its odometry (body pose; twist = the last step's (v, ω))."""
        v, om = self.base.vw[self.base.index[m.id]]
        self.odom[m.id].put(ros2.odom_to_ros(ros2.Odom(m.id, m.t, m.x, m.y, m.theta, float(v), float(om))))

    def new_bad_attachments(self) -> int:
        n, self.counted = self.node.bad_attachments - self.counted, self.node.bad_attachments
        return n

    def close(self) -> None:
        self.node.close()
