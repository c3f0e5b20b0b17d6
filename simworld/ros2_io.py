"""ROS 2 mode (`--ros2`) for the world: the robots' motion interface as ROS 2 topics over Zenoh.

Per robot i the plant publishes `/robot_<i>/odom` (nav_msgs/Odometry: body pose s_i, θ_i in frame `odom`,
child frame `robot_<i>/base_link`, stamp = simulated time, twist = the (v, ω) it moved with) instead of
its state key, and takes `/robot_<i>/cmd_vel` (geometry_msgs/Twist: linear.x = v, angular.z = ω) instead
of the command key, as ROS 2 node `simworld` with rmw_zenoh's keys, attachments and liveliness tokens
(reconswarm/net/ros2/ros2_node.py). Scans, clock and truth stay on the project's keys.

In this mode the world's state machine (simworld/world.py) has the plant a robot base is (`Ros2Robots`): it
holds the latest (v, ω) of each robot and moves the body on the exact arc (`unicycle.step_vw`, saturated to
the scenario's limits). A Twist carries no tick: the port takes a cmd_vel as the command of the oldest tick
whose odometry it published within `ros2_plan_age_periods` before the cmd_vel was sent (its attachment's
source timestamp; an agent sends none planned from an older one, agent/ros2_io.py), and the plant holds it
as the project's own mode holds a command of that tick: from where the robot stood then, a late one too,
while the robot stays within d_safe / 2 of that point and for `hold_sim_s` from that tick.
ROS 2 topics carry no tick, so ROS 2 mode is realtime only. `Ros2IO` is the world's robot interface in
this mode (simworld/robot_io.py `RobotIO`): the ROS 2 node `simworld`'s odometry publishers and cmd_vel subscriptions,
and each robot's scan on the project's key. The world node is the same as in the project's own mode, with
`Ros2Robots` as its plant.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
import zenoh

from reconswarm.net.node import Token
from reconswarm.net.ros2 import ros2
from reconswarm.net.ros2.ros2_node import Ros2Node
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.net.wire.wire import ClockMode
from reconswarm.plant import unicycle
from reconswarm.scenario.model import Scenario
from simworld.robot_io import token_or_cmd
from simworld.robots import Robots
from simworld.world import Command, WorldInput, WorldNode


class Ros2Robots(Robots):
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


def ros2_world(s: Scenario, speed: float, timing: Timing = TIMING) -> WorldNode:
    """The world node of ROS 2 mode: realtime, its plant a robot base (`Ros2Robots`)."""
    return WorldNode(s, ClockMode.REALTIME, speed, timing, Ros2Robots(s, timing.hold_sim_s))


def planned_tick(published_ns: dict[int, int], sent_ns: int, plan_age_ns: float) -> int:
    """The oldest tick whose odometry a cmd_vel sent at `sent_ns` can have been planned from: one published (tick ->
    when its odometries were out) at most `plan_age_ns` before it (agents send none planned from older:
    agent/ros2_io.py). The oldest keeps the plant's hold rules on the safe side: its reach is measured from where
    the robot stood then, its hold counted from then (`Robots.apply`). Both times are wall clocks' (the plant's
    for its odometry, the agent's for its cmd_vel, as the agent compared them): a constant offset between two
    machines' clocks cancels. Ros2Error: sent later than that after every odometry kept (clocks drifted apart)."""
    since = sent_ns - plan_age_ns
    got = [k for k, at_ns in published_ns.items() if at_ns >= since]
    if not got:
        newest = max(published_ns.values(), default=None)
        late = "" if newest is None else f" ({(since - newest) / 1e6:.1f} ms more after the newest)"
        raise ros2.Ros2Error(f"cmd_vel sent over {plan_age_ns / 1e6:.1f} ms after any odometry the plant published"
                             f"{late}: the agent's and the plant's clocks apart?")
    return min(got)


class Ros2IO:
    """The ROS 2 node `simworld`: an odom publisher and a cmd_vel subscription per robot; each robot's scan on the
    project's key (the robot interface `RobotIO`, simworld/robot_io.py).

    period_s: the run's period (wall seconds a tick lasts at its speed)."""

    def __init__(self, session: Any, keys: Keys, gate: Gate, domain_id: int, base: Ros2Robots, callback: Any,
                 period_s: float, timing: Timing = TIMING) -> None:
        """keys: the run's (scans go there); gate: the world's (admits each cmd_vel); callback(sample): where
        cmd_vel samples go (the process's inbox)."""
        self.base, self.keys, self.gate = base, keys, gate
        self.ros2_node = Ros2Node(session, domain_id, "simworld")
        self.odom = {a: self.ros2_node.publisher(ros2.odom_topic(a), ros2.ODOMETRY) for a in base.ids}
        block = zenoh.CongestionControl.BLOCK
        self.pub_scan = {a: session.declare_publisher(keys.scan(a), congestion_control=block) for a in base.ids}
        for a in base.ids:
            self.ros2_node.subscription(ros2.cmd_vel_topic(a), ros2.TWIST, callback)
        self.agent_of = {ros2.cmd_vel_key(domain_id, a): a for a in base.ids}
        self.counted = 0
        self.plan_age_ns = timing.ros2_plan_age_periods * period_s * 1e9
        self.keep_ticks = 2 * base.hold_ticks + 4  # (a cmd_vel dated older than the hold is stale anyway)
        self.published_ns: dict[int, int] = {}  # tick -> when its odometries were out (the last one's put, ns)

    def owns(self, key: str) -> bool:
        return key in self.agent_of

    def decode(self, key: str, payload: bytes, kind: str, source: str, at_s: float) -> WorldInput | None:
        """A cmd_vel as the command of the tick it was planned from, once the gate admitted it (first: a forger's
        timestamp is no excuse); a token as itself (the project's keys: no command comes there in this mode)."""
        if not self.owns(key):
            m = token_or_cmd(self.keys, key, payload, kind)
            return m if isinstance(m, Token) else None
        c, sent_ns = self.twist(key, payload, self.gate.world_k)
        if not self.gate.admit_twist(c, source, key, at_s):
            return None
        return Command(self.dated(c, sent_ns), at_s)

    def twist(self, key: str, payload: bytes, k: int) -> tuple[wire.Cmd, int | None]:
        """A cmd_vel sample as robot i's command of tick k (the newest published), and when it was sent (its
        attachment's source timestamp; None: unnoted); Ros2Error when it must be dropped. The port admits it
        (bounded, from agent i's session), then has it `dated` before the node holds it."""
        v, om = ros2.twist_from_ros(payload)
        return wire.Cmd(self.agent_of[key], k, v, om), self.ros2_node.sent.take(payload)

    def dated(self, c: wire.Cmd, sent_ns: int | None) -> wire.Cmd:
        """An admitted cmd_vel as the command of the tick it was planned from at the earliest (`planned_tick`;
        Ros2Error: sent too long after any odometry). A stop (a zero Twist) sent so late is dated stale instead:
        it moves nothing, and an agent behind the clock sends one once its robot's hold is over
        (agent/ros2_io.py), which tells the world it is alive although the plant applies nothing."""
        if sent_ns is None:  # (its attachment was checked on arrival: one whose time went unnoted is stale)
            return self.dated_stale(c)
        try:
            return dataclasses.replace(c, k=planned_tick(self.published_ns, sent_ns, self.plan_age_ns))
        except ros2.Ros2Error:
            if c.v_mps == 0.0 and c.omega_radps == 0.0:
                return self.dated_stale(c)
            raise

    def dated_stale(self, c: wire.Cmd) -> wire.Cmd:
        """c dated older than the plant holds any command (`keep_ticks` before the newest tick)."""
        return dataclasses.replace(c, k=c.k - self.keep_ticks)

    def put_state(self, m: wire.State) -> None:
        """A robot's state at this tick as its odometry, its scan on the project's key."""
        self.publish(m)
        if m.scan is not None:
            self.pub_scan[m.id].put(wire.scan_to_wire(m.scan))

    def publish(self, m: wire.State) -> None:
        """A robot's state at this tick as its odometry (body pose; twist = the last step's (v, ω))."""
        v, om = self.base.vw[self.base.index[m.id]]
        self.odom[m.id].put(ros2.odom_to_ros(ros2.Odom(m.id, m.t, m.x, m.y, m.theta, float(v), float(om))))
        self.published_ns[m.k] = time.time_ns()  # (after the put: never earlier than what its attachment says)
        if len(self.published_ns) > self.keep_ticks:
            del self.published_ns[min(self.published_ns)]

    def flush(self) -> None:  # (each state went out as its odometry)
        return None

    def dropped(self) -> list[tuple[str, str]]:
        """A cmd_vel sample without a valid rmw_zenoh attachment, each: dropped by the node before `decode`."""
        n, self.counted = self.ros2_node.bad_attachments - self.counted, self.ros2_node.bad_attachments
        return [("/robot_<i>/cmd_vel", "a sample without a valid rmw_zenoh attachment")] * n

    def close(self) -> None:
        self.ros2_node.close()
        for pub in self.pub_scan.values():
            pub.undeclare()
