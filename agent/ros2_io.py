"""ROS 2 mode (`--ros2`) for an agent: its robot's motion interface as ROS 2 topics over Zenoh.

Instead of its state and command keys, agent i reads `/robot_<i>/odom` (nav_msgs/Odometry: the body pose
s, θ and the simulated time) and publishes `/robot_<i>/cmd_vel` (geometry_msgs/Twist: linear.x = v,
angular.z = ω), as ROS 2 node `agent_<i>` with rmw_zenoh's keys, attachments and liveliness tokens
(reconswarm/net/ros2/ros2_node.py). The node (agent/node.py) does not change: an odometry becomes the state it
knows (head point p = s + l [cos θ, sin θ], tick k = round(t / dt)), and its command u becomes the Twist a robot
base holds: the (v, ω) whose arc over the step, from the state it was planned from, moves the head point by
exactly u dt, as the project's own plant moves it (not the continuous inverse (v, ω) = M(θ)⁻¹ u of eq. 3: held
as a twist over a step it turns the robot by |u| dt / l, and past |u| = 2 l / dt, 20 m/s in the paper, the head
point no longer goes toward u: the robot spins by a lost robot or an obstacle instead of keeping off it).

A Twist carries no tick, so the plant cannot tell which odometry a cmd_vel was planned from; it takes it as
planned from the oldest it published within `ros2_plan_age_periods` before the cmd_vel was sent (both
attachments' source timestamps), and the agent keeps to that: a command planned from an odometry published
longer ago is not sent (`stale`; the robot then holds its last cmd_vel under the plant's rules, then stops). Once
that hold is over the agent says so itself: a stop (a zero Twist), then one every `ros2_stop_every_s` while it
sends nothing else, so that the world keeps hearing from it (it counts an agent alive while its cmd_vels come,
reconswarm/net/trust/membership.py): on a machine behind the clock the robots stand and their agents stay alive.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from agent.messages import Received
from reconswarm.net.node import Invalid
from reconswarm.net.ros2 import ros2
from reconswarm.net.ros2.ros2_node import Ros2Node
from reconswarm.net.runtime.inbox import Rejections
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.plant import unicycle

log = logging.getLogger("reconswarm.agent")
KEEP_TICKS = 64  # the odometries' source timestamps kept (a command is planned from one of the newest)


@dataclass(frozen=True)
class Odometry:
    """A decoded odometry: the node's state, and when the plant published it (its attachment; None: unknown)."""

    state: wire.State
    sent_ns: int | None


class AgentRos2:
    """An agent's robot as ROS 2 topics: the robot interface of ROS 2 mode (agent/robot_io.py `RobotIO`)."""

    def __init__(self, session: Any, domain_id: int, agent_id: int, head_offset_m: float, dt_s: float,
                 callback: Any, timing: Timing = TIMING) -> None:
        """callback(sample): where odometry samples go (the host's inbox)."""
        self.id, self.l, self.dt, self.timing = agent_id, head_offset_m, dt_s, timing
        self.ros2_node = Ros2Node(session, domain_id, f"agent_{agent_id}")
        self.odom_key = ros2.odom_key(domain_id, agent_id)
        self.cmd_vel = self.ros2_node.publisher(ros2.cmd_vel_topic(agent_id), ros2.TWIST)
        self.ros2_node.subscription(ros2.odom_topic(agent_id), ros2.ODOMETRY, callback)
        self.counted = 0
        self.published_ns: dict[int, int] = {}  # tick -> when the plant published its odometry (its attachment)
        self.stale = 0  # commands not sent: planned from an odometry older than `ros2_plan_age_periods`
        self.stops = 0  # stops sent instead, once the plant's hold was over
        self.sent_ns: int | None = None  # when the last cmd_vel went out (a plan or a stop)
        self.stopping = False  # the last one was a stop
        self._told_s = -math.inf

    def own_keys(self, keys: Keys) -> list[tuple[str, bool]]:
        """The scan stays on the project's key (its odometry comes through our own subscription)."""
        return [(keys.scan(self.id), False)]

    def owns(self, key: str) -> bool:
        return key == self.odom_key

    def decode(self, key: str, payload: bytes, source: str, gate: Gate, rej: Rejections) -> Received | None:
        """An odometry sample as the node's state, once the gate admitted it: the plant's (the world's session), a
        pose the robot can have reached (else refused and counted); Invalid (counted) when malformed."""
        odom = self.odometry(key, payload)
        if isinstance(odom, Invalid):
            rej.reject(key, odom.reason)
            return odom
        if not gate.admit_odometry(odom.state, source, key, time.monotonic()):
            return None
        self.keep(odom)
        return odom.state

    def odometry(self, key: str, payload: bytes) -> Odometry | Invalid:
        """An odometry sample as the node's state at tick round(t / dt), and when the plant published it."""
        try:
            o = ros2.odom_from_ros(payload, self.id)
        except ros2.Ros2Error as exc:
            return Invalid(key, str(exc))
        k = round(o.t_s / self.dt)
        px, py = o.x_m + self.l * math.cos(o.theta_rad), o.y_m + self.l * math.sin(o.theta_rad)
        # (its scan: on its own key)
        state = wire.State(self.id, k, o.t_s, o.x_m, o.y_m, o.theta_rad, px, py)
        return Odometry(state, self.ros2_node.sent.take(payload))

    def keep(self, o: Odometry) -> None:
        """An admitted odometry (the plant's): when its tick was published, what a command of that tick is judged
        by (`command`)."""
        if o.sent_ns is not None:
            self.published_ns[o.state.k] = o.sent_ns
            if len(self.published_ns) > KEEP_TICKS:
                del self.published_ns[min(self.published_ns)]

    def command(self, c: wire.Cmd, period_s: float) -> None:
        self.send(c, period_s)

    def send(self, c: wire.Cmd, period_s: float, now_ns: int | None = None) -> bool:
        """The node's command as the Twist a robot base holds (`twist`), stamped `now_ns` (None: the wall clock's
        now), unless the odometry of its tick was published more than `ros2_plan_age_periods` of `period_s` (the
        run's period, wall s) before: False, not sent; a stop is sent instead once the last cmd_vel is older than
        the plant's hold (`hold_sim_s`, in wall time at this period), then every `ros2_stop_every_s`."""
        now_ns = time.time_ns() if now_ns is None else now_ns
        basis_ns = self.published_ns.get(c.k)
        budget_ns = self.timing.ros2_plan_age_periods * period_s * 1e9
        if basis_ns is not None and now_ns - basis_ns <= budget_ns:
            self._send(*self.twist(c), now_ns)
            self.stopping = False
            return True
        self.stale += 1
        hold_ns = self.timing.hold_sim_s / self.dt * period_s * 1e9
        wait_ns = self.timing.ros2_stop_every_s * 1e9 if self.stopping else hold_ns
        if self.sent_ns is None or now_ns - self.sent_ns >= wait_ns:  # (the plant has stopped the robot already)
            self._send(0.0, 0.0, now_ns)
            self.stops += 1
            self.stopping = True
        if time.monotonic() - self._told_s >= 5.0:
            self._told_s = time.monotonic()
            age = "unknown" if basis_ns is None else f"{(now_ns - basis_ns) / 1e6:.1f} ms"
            log.warning("agent %d: a command not sent: planned from odometry published %s ago, more than %.1f ms "
                        "(the machine is behind the clock) [total %d; %d stops sent instead]", self.id, age,
                        budget_ns / 1e6, self.stale, self.stops)
        return False

    def twist(self, c: wire.Cmd) -> tuple[float, float]:
        """The twist a robot base holds for the node's command (v, ω) = M(θ)⁻¹ u: the one whose arc over a step
        moves the head point by exactly u dt (unicycle.arc_twist: held as a twist, the node's own spins the robot
        in place once |u| passes 2 l / dt)."""
        return unicycle.arc_twist(c.v_mps, c.omega_radps, self.l, self.dt)

    def _send(self, v_mps: float, omega_radps: float, now_ns: int) -> None:
        self.cmd_vel.put(ros2.twist_to_ros(v_mps, omega_radps), now_ns)
        self.sent_ns = now_ns

    def dropped(self) -> list[Invalid]:
        """Samples dropped for their attachment since the last call (for the node to count)."""
        n, self.counted = self.ros2_node.bad_attachments - self.counted, self.ros2_node.bad_attachments
        return [Invalid(self.odom_key, "odometry without a valid rmw_zenoh attachment")] * n

    def close(self) -> None:
        self.ros2_node.close()


def ros2_robot(domain_id: int) -> Callable[..., AgentRos2]:
    """The robot interface of every agent of a process in ROS 2 mode, in that domain (agent/robot_io.py
    `RobotFactory`)."""

    def make(session: Any, keys: Keys, agent_id: int, l_m: float, dt_s: float, timing: Timing,
             callback: Callable[[Any], None]) -> AgentRos2:
        return AgentRos2(session, domain_id, agent_id, l_m, dt_s, callback, timing)

    return make
