"""The world's robot interface: how robots' states go out and their commands come in, chosen once per process.

`RobotIO` is what the world's port (simworld/process.py) needs of it; two interfaces implement it:

- `KeysIO`, the project's keys: one message per agent host and tick each way, the states of its agents (their
  scans inside) on `host/<hid>/state`, their commands on `host/<hid>/cmd` (reconswarm/net/wire/hostwire.py,
  docs/wire.md); who a host speaks for is its liveliness token's (simworld/hosts.py);
- `simworld/ros2_io.Ros2IO`, ROS 2 topics through rmw_zenoh: `/robot_<i>/odom` out, `/robot_<i>/cmd_vel` in, the
  scan on the project's `scan` key (docs/ros2.md).

Both decode what they subscribed to into the world node's input: a `Command` the gate admitted, a liveliness token
(shared: `token_or_cmd`), or None (refused by the gate, which counts and logs it, or not the world's); a command
batch is the list of the commands admitted; a malformed sample raises WireError (or ros2.Ros2Error), which the port
counts as invalid. The states of a tick are put as the node returns them and go out at `flush` (after the tick's
last), one message per host.
"""

from __future__ import annotations

from typing import Any, Protocol

import zenoh

from reconswarm.net.node import Role, Token
from reconswarm.net.runtime import trace
from reconswarm.net.trust.admission import Intrusion, IntrusionKind
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.decode import WORLD as ACCEPTS
from reconswarm.net.wire.decode import decode
from reconswarm.net.wire.hostwire import CmdBatch, attachment, state_batches
from reconswarm.net.wire.keys import Keys
from simworld.hosts import Hosts
from simworld.world import Command, WorldInput


class RobotIO(Protocol):
    """The robots' side of the world's port: what it declared, how a sample becomes the node's input, where a
    state goes."""

    def decode(self, key: str, payload: bytes, kind: str, source: str,
               at_s: float) -> WorldInput | list[WorldInput] | None: ...

    def put_state(self, m: wire.State) -> None: ...

    def flush(self) -> None:
        """Send the states put since the last call."""
        ...

    def dropped(self) -> list[tuple[str, str]]:
        """(key, reason) of each sample the interface dropped before it reached `decode` since the last call."""
        ...

    def close(self) -> None: ...


def token_or_cmd(keys: Keys, key: str, payload: bytes, kind: str) -> Token | wire.Cmd | CmdBatch | None:
    """A sample on the world's keys as a token or a command batch (None: another kind); WireError when malformed."""
    m = decode(keys, ACCEPTS, key, payload, kind)
    return m if isinstance(m, Token | wire.Cmd | CmdBatch) else None


class KeysIO:
    """The project's keys: a publisher per host's states (declared as its token comes), one subscription to every
    host's commands."""

    def __init__(self, session: zenoh.Session, keys: Keys, ids: list[int], gate: Gate, handler: Any) -> None:
        """handler: the process inbox's subscriber handler."""
        self.z, self.keys, self.gate = session, keys, gate
        self.hosts = Hosts()
        self.pub_state: dict[int, Any] = {}  # hid -> its states' publisher
        self.states: list[wire.State] = []  # put since the last flush
        self.held: dict[int, Token] = {}  # agents' tokens that came before a host spoke for them
        self.sub = session.declare_subscriber(keys.host(None, "cmd"), handler)

    def decode(self, key: str, payload: bytes, kind: str, source: str,
               at_s: float) -> WorldInput | list[WorldInput] | None:
        """A host's token tells whom it speaks for; an agent's token counts for the node once a host speaks for it
        (its states have somewhere to go: held until then, so the mission's start or an agent's return is never a
        tick its states are lost for)."""
        m = token_or_cmd(self.keys, key, payload, kind)
        if isinstance(m, Token) and m.role is Role.HOST:
            assert m.agent is not None
            self.hosts.token(m.agent, m.members, m.up)
            return [self.held.pop(a) for a in m.members if a in self.held and a in self.hosts.owner]
        if isinstance(m, Token) and m.role is Role.AGENT and m.agent is not None:
            self.held.pop(m.agent, None)
            if m.up and m.agent not in self.hosts.owner:
                self.held[m.agent] = m
                return None
            return m
        if isinstance(m, CmdBatch):
            return list(self.commands(m, key, source, at_s))
        return m if isinstance(m, Token) else None

    def commands(self, b: CmdBatch, key: str, source: str, at_s: float) -> list[Command]:
        """The commands of a host's batch the gate admits: only for the agents that host speaks for (a batch naming
        another's is one intrusion, and those rows are not believed)."""
        foreign = [c.id for c in b.cmds if not self.hosts.speaks_for(b.host, c.id)]
        if foreign:
            why = f"host {b.host} does not speak for agent(s) {foreign[:8]}"
            self.gate.refuse(Intrusion(IntrusionKind.IMPERSONATION, source, key, why), at_s)
        out = []
        trace.mark(trace.Mark.HOST_CMD_IN, b.cmds[0].k, b.host, at_s)
        for c in b.cmds:
            if c.id not in foreign and self.gate.admit(c, source, key, at_s):
                trace.mark(trace.Mark.CMD_IN, c.k, c.id, at_s)
                out.append(Command(c, at_s))
        return out

    def put_state(self, m: wire.State) -> None:
        self.states.append(m)

    def flush(self) -> None:
        if not self.states:
            return
        by_id = {m.id: m for m in self.states}
        self.states = []
        for hid, ids in self.hosts.group(list(by_id)).items():
            pub = self.pub_state.get(hid)
            if pub is None:
                pub = self.pub_state[hid] = self.z.declare_publisher(self.keys.host(hid, "state"),
                                                                     congestion_control=zenoh.CongestionControl.BLOCK)
            states = [by_id[a] for a in ids]
            for st in states:  # (marked before the put: its arrival is never stamped earlier)
                trace.mark(trace.Mark.STATE_PUT, st.k, st.id)
            for payload, n in state_batches(hid, states):
                trace.mark(trace.Mark.HOST_STATE_PUT, states[0].k, hid)
                pub.put(payload, attachment=attachment(n))

    def dropped(self) -> list[tuple[str, str]]:
        return []

    def close(self) -> None:
        self.sub.undeclare()
        for pub in self.pub_state.values():
            pub.undeclare()
