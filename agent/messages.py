"""What an agent's node takes in and gives out (the node contract, reconswarm/net/node.py): the wire dataclasses
plus tokens and the runtime's verdicts in; messages to put, the cells to listen to, and what to do out."""

from __future__ import annotations

from dataclasses import dataclass

from agent.brain import Plan
from agent.neighbours import Cells
from reconswarm.net.node import Exit, Invalid, RouterReach, Stop, Token
from reconswarm.net.wire import wire


@dataclass(frozen=True)
class Law:
    """The command of tick k from our `Plan`, as our unicycle's (v, ω), computed by our host with its other agents'
    (agent/host.py, agent/brain.py `commands`)."""

    k: int
    v_mps: float
    omega_radps: float


# inputs: the wire messages an agent reads, plus the runtime's (reconswarm/net/node.py): a peer's or the world's
# token (Token with Role.AGENT and its id, or Role.WORLD), a message dropped as invalid, our router link, a signal
# (all that a sample or the runtime brings: Received; what the node keeps of it is agent/heard.py's `Heard`); and
# the law our host computed for our plan
Received = wire.State | wire.Scan | wire.Clock | wire.Beacon | wire.ObstacleSet | Token | Invalid | RouterReach | Stop
Input = Received | Law


# ----------------------------------------------------------------------------------------- outputs
@dataclass(frozen=True)
class Reconnect:
    """No command for `resubscribe_s` though the mission goes on: open a new session (keep this node)."""


# Plan: our tick ready for the law, which our host computes for all its agents at once (then `Law`)
Output = Cells | wire.Beacon | wire.ObstacleSet | wire.Cmd | Reconnect | Exit | Plan
