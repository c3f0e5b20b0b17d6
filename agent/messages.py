"""What an agent's node takes in and gives out (the node contract, reconswarm/net/node.py): the wire dataclasses
plus tokens and the runtime's verdicts in; messages to put, the cells to listen to, and what to do out."""

from __future__ import annotations

from dataclasses import dataclass

from agent.neighbours import Cells
from reconswarm.net import wire
from reconswarm.net.node import Exit, Invalid, RouterLink, Stop, Token

# inputs: the wire messages an agent reads, plus the runtime's (reconswarm/net/node.py): a peer's or the world's
# token (Token with Role.AGENT and its id, or Role.WORLD), a message dropped as invalid, our router link, a signal
Input = wire.State | wire.Scan | wire.Clock | wire.Beacon | wire.ObstacleSet | Token | Invalid | RouterLink | Stop


# ----------------------------------------------------------------------------------------- outputs
@dataclass(frozen=True)
class Reconnect:
    """No command for `resubscribe_s` though the mission goes on: open a new session (keep this node)."""


Output = Cells | wire.Beacon | wire.ObstacleSet | wire.Cmd | Reconnect | Exit
