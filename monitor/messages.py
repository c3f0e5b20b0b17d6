"""What the monitor's node takes in and gives out (the node contract, reconswarm/net/node.py).

Inputs: the admitted wire messages it reads (the world's truth, the world's clock with the session it came
from, another process's report), plus the runtime's: a process's token (Token with Role.AGENT and its id, or
Role.WORLD), a message dropped as invalid (counted), our own router link, a signal.
Outputs: events (recorded, then published on `swarm/<run>/event`, in order), rows for the record
(monitor/rows.py), ends refused (for the process's gate to count as intrusions), and Exit.
"""

from __future__ import annotations

from dataclasses import dataclass

from monitor.rows import Record
from reconswarm.net import wire
from reconswarm.net.node import Exit, Invalid, RouterLink, Stop, Token
from reconswarm.net.report import Report
from reconswarm.paper.events import Event


# ------------------------------------------------------------------------------------------ inputs
@dataclass(frozen=True)
class ClockFrom:
    """The world's clock, admitted, with the session it came from (`inbox.sample_source`): an end it claims is
    refused as that session's intrusion if the world's next clock or the truth contradicts it."""

    clock: wire.Clock
    source: str


Input = ClockFrom | wire.Truth | Report | Token | Invalid | RouterLink | Stop


# ----------------------------------------------------------------------------------------- outputs
@dataclass(frozen=True)
class RefusedEnd:
    """An end the world did not decide (its next clock goes on, or the truth is not converged): the session that
    claimed it is counted as an intrusion (kind `end`) by the process's gate; the recording goes on."""

    source: str
    why: str


Output = Event | Record | RefusedEnd | Exit
