"""What an agent's node takes in and gives out: the wire dataclasses plus membership and the adapter's
own verdicts (agent/node.py is the state machine over them)."""

from __future__ import annotations

from dataclasses import dataclass

from agent.neighbours import Cells
from reconswarm.net import wire


# ------------------------------------------------------------------------------------------ inputs
@dataclass(frozen=True)
class Joined:
    """An agent's liveliness token appeared."""

    agent: int


@dataclass(frozen=True)
class Left:
    """An agent's liveliness token went away."""

    agent: int


@dataclass(frozen=True)
class WorldToken:
    """The world's liveliness token appeared (up) or went away (its process stopped, or froze past its lease)."""

    up: bool


@dataclass(frozen=True)
class Invalid:
    """A message the adapter dropped (undecodable, or on our own key from another session): counted."""

    key: str
    reason: str


Input = wire.State | wire.Scan | wire.Clock | wire.Beacon | wire.ObstacleSet | Joined | Left | WorldToken | Invalid


# ----------------------------------------------------------------------------------------- outputs
@dataclass(frozen=True)
class Reconnect:
    """No command for `resubscribe_s` though the mission goes on: open a new session (keep this node)."""


@dataclass(frozen=True)
class Exit:
    """Leave the loop with this exit code (0: the world ended the mission; 3: the world went silent)."""

    code: int


Output = Cells | wire.Beacon | wire.ObstacleSet | wire.Cmd | Reconnect | Exit
