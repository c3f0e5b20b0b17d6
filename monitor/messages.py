"""What the monitor's node takes in and gives out (the node contract, reconswarm/net/node.py).

Inputs: the admitted wire messages it reads (the world's truth, the world's clock with the session it came
from, another process's report), plus the runtime's: a process's token (Token with Role.AGENT and its id, or
Role.WORLD), a message dropped as invalid (counted), our own router link, a signal.
Outputs: events (recorded, then published on `swarm/<run>/event`, in order), rows for the record
(monitor/rows.py), ends refused (for the process's gate to count as intrusions), the scene of the newest tick
recorded (for the live views: the Foxglove view, the terminal's table), and Exit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from monitor.rows import Record
from reconswarm.net.node import Exit, Invalid, RouterReach, Stop, Token
from reconswarm.net.wire import wire
from reconswarm.net.wire.report import Report
from reconswarm.paper.events import Event


# ------------------------------------------------------------------------------------------ inputs
@dataclass(frozen=True)
class ClockFrom:
    """The world's clock, admitted, with the session it came from (`inbox.sample_source`): an end it claims is
    refused as that session's intrusion if the world's next clock or the truth contradicts it."""

    clock: wire.Clock
    source: str


Input = ClockFrom | wire.Truth | Report | Token | Invalid | RouterReach | Stop


# ----------------------------------------------------------------------------------------- outputs
@dataclass(frozen=True)
class RefusedEnd:
    """An end the world did not decide (its next clock goes on, or the truth is not converged): the session that
    claimed it is counted as an intrusion (kind `end`) by the process's gate; the recording goes on."""

    source: str
    why: str


@dataclass(frozen=True)
class Scene:
    """The newest tick a step recorded, as the live views show it (arrays in scenario order, copies)."""

    k: int
    t_s: float
    p: NDArray[np.float64]  # (N, 2) head points
    theta: NDArray[np.float64]  # (N,) headings
    alive: NDArray[np.bool_]  # (N,) alive as recorded
    edges: NDArray[np.int64]  # (E, 2) the swarm graph's index pairs
    n_groups: int
    max_error_m: float
    gaps_m: tuple[float, float]  # this tick's smallest agent and obstacle gaps
    min_gap_m: float  # the smallest agent gap of the run so far
    rejected: int  # messages the run's other processes and this one dropped


Output = Event | Record | RefusedEnd | Scene | Exit
