"""An agent's robot interface: its robot's state in, its command out, chosen once per process (agent/process.py).

`RobotIO` is what an agent's link (agent/link.py) and its host (agent/host.py) need of it; two interfaces
implement it:

- `KeysRobot`, the project's keys: the robot's state (its scan inside) on `agent/<id>/state`, the command on
  `agent/<id>/cmd` (reconswarm/net/wire/keys.py, docs/wire.md);
- `agent/ros2_io.AgentRos2`, ROS 2 topics through rmw_zenoh: `/robot_<i>/odom` in (its own subscription), the
  scan on the project's `scan` key, `/robot_<i>/cmd_vel` out (docs/ros2.md).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import zenoh

from agent.messages import Received
from reconswarm.net.node import Invalid
from reconswarm.net.runtime import trace
from reconswarm.net.runtime.inbox import Rejections
from reconswarm.net.timing import Timing
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys


class RobotIO(Protocol):
    """One agent's robot, as its link and host reach it."""

    def own_keys(self, keys: Keys) -> list[tuple[str, bool]]:
        """The project's keys the host subscribes to for this agent alone, each with whether a sample there starts
        a tick (urgent)."""
        ...

    def owns(self, key: str) -> bool:
        """A sample that only this interface decodes (`decode`); the rest go through the decode table."""
        ...

    def decode(self, key: str, payload: bytes, source: str, gate: Gate, rej: Rejections) -> Received | None:
        """A sample it owns as the node's input (None: refused by the gate, which counts it; Invalid: counted)."""
        ...

    def command(self, c: wire.Cmd, period_s: float) -> None:
        """Send the node's command to the robot (period_s: the run's period, wall seconds a tick lasts)."""
        ...

    def dropped(self) -> list[Invalid]:
        """Samples dropped before they reached `decode` since the last call (for the node to count)."""
        ...

    def close(self) -> None: ...


# The robot interface of one agent on a session: (session, agent id, head offset (m), dt (s), timing,
# callback(sample) for the samples it subscribes to itself) -> RobotIO.
RobotFactory = Callable[[zenoh.Session, Keys, int, float, float, Timing, Callable[[Any], None]], RobotIO]


class KeysRobot:
    """The project's keys: the state comes through the host's subscription (`own_keys`), the command goes out on its
    publisher."""

    def __init__(self, session: zenoh.Session, keys: Keys, agent_id: int) -> None:
        self.pub_cmd: zenoh.Publisher | None = session.declare_publisher(
            keys.cmd(agent_id), congestion_control=zenoh.CongestionControl.BLOCK)
        self.id = agent_id

    def own_keys(self, keys: Keys) -> list[tuple[str, bool]]:
        return [(keys.state(self.id), True)]

    def owns(self, key: str) -> bool:
        return False

    def decode(self, key: str, payload: bytes, source: str, gate: Gate, rej: Rejections) -> Received | None:
        raise AssertionError("the project's keys decode through the decode table")

    def command(self, c: wire.Cmd, period_s: float) -> None:
        if self.pub_cmd is not None:
            self.pub_cmd.put(wire.cmd_to_wire(c))
            trace.mark(trace.Mark.CMD_PUT, c.k, c.id)

    def dropped(self) -> list[Invalid]:
        return []

    def close(self) -> None:  # (a link closes when its agent fails and again with its host)
        if self.pub_cmd is not None:
            self.pub_cmd.undeclare()
            self.pub_cmd = None


def keys_robot(session: zenoh.Session, keys: Keys, agent_id: int, _l_m: float, _dt_s: float, _timing: Timing,
               _callback: Callable[[Any], None]) -> RobotIO:
    return KeysRobot(session, keys, agent_id)
