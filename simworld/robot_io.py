"""The world's robot interface: how robots' states go out and their commands come in, chosen once per process.

`RobotIO` is what the world's port (simworld/process.py) needs of it; two interfaces implement it:

- `KeysIO`, the project's keys: each robot's state (its scan inside) on `agent/<id>/state`, each agent's command
  on `agent/<id>/cmd` (reconswarm/net/wire/keys.py, docs/wire.md);
- `simworld/ros2_io.Ros2IO`, ROS 2 topics through rmw_zenoh: `/robot_<i>/odom` out, `/robot_<i>/cmd_vel` in, the
  scan on the project's `scan` key (docs/ros2.md).

Both decode what they subscribed to into the world node's input: a `Command` the gate admitted, a liveliness token
(shared: `token_or_cmd`), or None (refused by the gate, which counts and logs it, or not the world's); a malformed
sample raises WireError (or ros2.Ros2Error), which the port counts as invalid.
"""

from __future__ import annotations

from typing import Any, Protocol

import zenoh

from reconswarm.net.node import Token
from reconswarm.net.runtime import trace
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.decode import WORLD as ACCEPTS
from reconswarm.net.wire.decode import decode
from reconswarm.net.wire.keys import Keys
from simworld.world import Command, WorldInput


class RobotIO(Protocol):
    """The robots' side of the world's port: what it declared, how a sample becomes the node's input, where a
    state goes."""

    def decode(self, key: str, payload: bytes, kind: str, source: str, at_s: float) -> WorldInput | None: ...

    def put_state(self, m: wire.State) -> None: ...

    def dropped(self) -> list[tuple[str, str]]:
        """(key, reason) of each sample the interface dropped before it reached `decode` since the last call."""
        ...

    def close(self) -> None: ...


def token_or_cmd(keys: Keys, key: str, payload: bytes, kind: str) -> Token | wire.Cmd | None:
    """A sample on the world's keys as a token or a command (None: another kind); WireError when malformed."""
    m = decode(keys, ACCEPTS, key, payload, kind)
    return m if isinstance(m, Token | wire.Cmd) else None


class KeysIO:
    """The project's keys: a publisher per robot's state, one subscription to every agent's command."""

    def __init__(self, session: zenoh.Session, keys: Keys, ids: list[int], gate: Gate, handler: Any) -> None:
        """handler: the process inbox's subscriber handler."""
        block = zenoh.CongestionControl.BLOCK
        self.keys, self.gate = keys, gate
        self.pub_state = {a: session.declare_publisher(keys.state(a), congestion_control=block) for a in ids}
        self.sub = session.declare_subscriber(keys.all_agents("cmd"), handler)

    def decode(self, key: str, payload: bytes, kind: str, source: str, at_s: float) -> WorldInput | None:
        m = token_or_cmd(self.keys, key, payload, kind)
        if not isinstance(m, wire.Cmd):
            return m
        if not self.gate.admit(m, source, key, at_s):
            return None
        trace.mark(trace.Mark.CMD_IN, m.k, m.id, at_s)
        return Command(m, at_s)

    def put_state(self, m: wire.State) -> None:
        self.pub_state[m.id].put(wire.state_to_wire(m))
        trace.mark(trace.Mark.STATE_PUT, m.k, m.id)

    def dropped(self) -> list[tuple[str, str]]:
        return []

    def close(self) -> None:
        self.sub.undeclare()
