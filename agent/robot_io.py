"""An agent's robot interface: its robot's state in, its command out, chosen once per process (agent/process.py).

`RobotIO` is what an agent's link (agent/hosted.py) and its host (agent/host.py) need of it; two interfaces
implement it:

- `KeysRobot`, the project's keys, through its host's `HostKeys`: one message per host and tick each way, the
  states of the host's agents (their scans inside) on `host/<hid>/state`, their commands of a round of the host's
  loop on `host/<hid>/cmd` (reconswarm/net/wire/hostwire.py, docs/wire.md);
- `agent/ros2_io.AgentRos2`, ROS 2 topics through rmw_zenoh: `/robot_<i>/odom` in (its own subscription), the
  scan on the project's `scan` key, `/robot_<i>/cmd_vel` out (docs/ros2.md).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Container, Mapping
from typing import Any, Protocol

import zenoh

from agent.messages import Input, Received
from reconswarm.net.node import Invalid
from reconswarm.net.runtime import trace
from reconswarm.net.runtime.inbox import Rejections, Tag
from reconswarm.net.timing import Timing
from reconswarm.net.trust.admission import Intrusion, IntrusionKind
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import BeaconBatch
from reconswarm.net.wire.hostwire import StateBatch, attachment, cmds_to_wire
from reconswarm.net.wire.keys import Keys

Decoded = Received | BeaconBatch | StateBatch | None  # what a sample decodes to (None: a key no agent reads)


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


STATES: Tag = ("states", None)  # the tag of the host's state batches in its inbox (net/runtime/inbox.py)


class HostKeys:
    """A host's robots on the project's keys: one subscription to its agents' states, one publisher of their
    commands (what its agents' `KeysRobot`s command in a round goes out in one message, at `flush`)."""

    def __init__(self, session: zenoh.Session, keys: Keys, ids: tuple[int, ...]) -> None:
        self.z, self.keys, self.hid = session, keys, min(ids)
        self.pub: zenoh.Publisher | None = session.declare_publisher(
            keys.host(self.hid, "cmd"), congestion_control=zenoh.CongestionControl.BLOCK)
        self.cmds: dict[tuple[int, int], wire.Cmd] = {}  # (agent, tick) -> its command of this round, in order

    def subscribe(self, handler: Callable[[Tag, bool, bool], Any]) -> Any:
        """Our agents' states: urgent (they start a tick), counted for the rows each carries."""
        return self.z.declare_subscriber(self.keys.host(self.hid, "state"), handler(STATES, True, True))

    def add(self, c: wire.Cmd) -> None:
        """An agent's command of this round; one it sends again in the same round (its tick seen again more than
        once) replaces the earlier one of that tick."""
        self.cmds.pop((c.id, c.k), None)  # (the newer goes last, as it came)
        self.cmds[c.id, c.k] = c
        trace.mark(trace.Mark.CMD_PUT, c.k, c.id)

    def flush(self) -> None:
        """Put the commands of this round, in one message."""
        if self.cmds and self.pub is not None:
            cmds = list(self.cmds.values())
            trace.mark(trace.Mark.HOST_CMD_PUT, cmds[0].k, self.hid)
            # (its attachment: the rows the world's inbox counts it for)
            self.pub.put(cmds_to_wire(self.hid, cmds), attachment=attachment(len(cmds)))
        self.cmds = {}

    def close(self) -> None:
        self.flush()
        if self.pub is not None:
            self.pub.undeclare()
            self.pub = None


def take_states(m: Decoded, key: str, source: str, at_s: float, active: Mapping[int, Any], hosted: Container[int],
                gate: Gate, batches: dict[int, list[Input]]) -> None:
    """A host's state batch, taken apart once: each state for its agent (if still running). Malformed: counted once
    (by the lowest running agent); not from the world, or naming an agent we do not host: one intrusion, and those
    rows not believed."""
    if not active:
        return
    first = active[min(active)]
    if not isinstance(m, StateBatch):
        got = None if m is None else first.take(m, key, source)
        if got is not None:
            batches[first.id].append(got)
        return
    now = time.monotonic()
    bad = gate.check(m.states[0], source, key, now)
    if bad is None and (foreign := [st.id for st in m.states if st.id not in hosted]):
        bad = Intrusion(IntrusionKind.IMPERSONATION, source, key, f"states of agents {foreign[:8]}, not hosted here")
    if bad is not None:
        first.gate.refuse(bad, now)
        if bad.kind is not IntrusionKind.IMPERSONATION:
            return
    trace.mark(trace.Mark.HOST_STATE_IN, m.states[0].k, m.host, at_s)
    for st in m.states:
        if st.id in active and st.id in hosted:
            batches[st.id].append(st)
            trace.mark(trace.Mark.STATE_IN, st.k, st.id, at_s)


class KeysRobot:
    """The project's keys: the state comes in its host's batch (`HostKeys`, taken apart by `take_states`), the
    command goes out in its host's batch of the round (`out`: its host's, bound by the host, agent/host.py)."""

    def __init__(self, out: HostKeys | None, agent_id: int) -> None:
        self.out, self.id = out, agent_id

    def own_keys(self, keys: Keys) -> list[tuple[str, bool]]:
        return []

    def owns(self, key: str) -> bool:
        return False

    def decode(self, key: str, payload: bytes, source: str, gate: Gate, rej: Rejections) -> Received | None:
        raise AssertionError("the project's keys decode through the decode table")

    def command(self, c: wire.Cmd, period_s: float) -> None:
        assert self.out is not None, "a hosted agent's robot is bound to its host's keys"
        self.out.add(c)

    def dropped(self) -> list[Invalid]:
        return []

    def close(self) -> None:  # (the host's publisher is its HostKeys')
        return None


def keys_robot(_session: zenoh.Session, _keys: Keys, agent_id: int, _l_m: float, _dt_s: float, _timing: Timing,
               _callback: Callable[[Any], None]) -> RobotIO:
    """An agent's robot on the project's keys, bound to its host's `HostKeys` by the host (agent/host.py)."""
    return KeysRobot(None, agent_id)
