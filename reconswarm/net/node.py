"""One node contract for every role: `step(inputs, now_s) -> outputs`.

An agent, the world and the monitor are each a pure state machine (agent/node.py, simworld/world.py,
monitor/node.py): no clock of its own, no I/O, no zenoh. Its process's runtime hands it, in one batch, the
inputs that arrived (decoded and admitted: what the node sees is believed) with the wall time, and does what
the step returns, in order: put a message on the wire (a wire dataclass: its key is the runtime's choice,
the project's keys or ROS 2 topics), hand rows to the record, exit. Between batches the runtime steps a node
when its timer is due (`wake_at_s`) with no inputs: that is its timer.

Inputs every role shares are defined here (a process's liveliness token, a message dropped as invalid, our
own session's router link, a request to stop); each role adds its wire messages. Outputs every role shares:
`Exit`. Rules live in the node that owns them: who is alive (membership: token AND own data) is decided
once per role, inside its node, from the `Token`s and admitted messages it is given.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Protocol, TypeVar


class Role(Enum):
    """Who a liveliness token stands for (its key's leaf: `alive/agent/<i>`, `alive/host/<hid>/<members>`,
    `alive/simworld`, `alive/monitor`)."""

    AGENT = "agent"
    HOST = "host"
    WORLD = "simworld"
    MONITOR = "monitor"


# ------------------------------------------------------------------------------------------ inputs
@dataclass(frozen=True)
class Token:
    """A process's liveliness token appeared (up) or went away (its process stopped, or froze past its
    lease); `agent` is the agent's id for Role.AGENT, the host's id for Role.HOST (None otherwise); `members`: the
    agents a host speaks for (Role.HOST)."""

    role: Role
    up: bool
    agent: int | None = None
    members: tuple[int, ...] = ()


@dataclass(frozen=True)
class Invalid:
    """A message the runtime dropped (undecodable, out of bounds, or on our own key from another session):
    the node counts it, never believes it."""

    key: str
    reason: str


@dataclass(frozen=True)
class RouterReach:
    """Our own session lost (up=False) or regained its router: nobody else's loss (net/runtime/uplink.py)."""

    up: bool


@dataclass(frozen=True)
class Stop:
    """The process was asked to stop (SIGINT/SIGTERM): wind down and say what happened."""


# ----------------------------------------------------------------------------------------- outputs
@dataclass(frozen=True)
class Exit:
    """Leave the loop with this exit code; `reason` says why (the world's: the mission's end reason)."""

    code: int
    reason: str = ""


In = TypeVar("In", contravariant=True)
Out = TypeVar("Out", covariant=True)


class Node(Protocol[In, Out]):
    """The contract: pure, stepped by a runtime with what arrived and the wall time."""

    def step(self, inputs: Sequence[In], now_s: float) -> Sequence[Out]:
        """Take the inputs that arrived by now_s (none: a timer), return what to do, in order."""
        ...

    def wake_at_s(self) -> float | None:
        """When to be stepped at the latest even if nothing arrives (None: only when something does)."""
        ...

    def awaiting(self, now_s: float) -> int | None:
        """How many more messages the node needs before a step can move it on (the runtime sleeps until that
        many are in, an urgent one, or `wake_at_s`); None: only an urgent message or the timer will."""
        ...
