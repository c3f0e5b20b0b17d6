"""Record decimation (`reconswarm sim --record-period S`): a tick row every `every` ticks instead of every tick.

A tick row holds every agent's head point, heading and alive flag: 25 bytes per agent (three float64 and a
byte), so 2.5 MB per tick at 100,000 agents, 50 MB per simulated second at dt 0.05 s. Decimation is chosen,
never the default. What it keeps exact:

- the last tick the run reaches (held back, written by `finish`): the final error and the convergence time;
- the smallest agent and obstacle gaps: a written row carries the smallest gaps of every tick since the
  row before it, so the summary's minimum gaps are those of every tick;
- events, safety episodes (their own tables, written at every tick as they happen).

What it coarsens: positions between rows (path lengths are those of the polyline through the rows).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from reconswarm.paper.events import Event
from reconswarm.record.recorder import Rows
from reconswarm.record.safety import Episode

Array = NDArray[np.float64]

BYTES_PER_AGENT_TICK = 3 * 8 + 1  # a tick row's blobs: x, y, heading (float64) and alive (a byte) per agent


def record_bytes(n_agents: int, rows: int) -> int:
    """The tick rows' blobs of a record of n agents and this many rows (SQLite's pages add a few %)."""
    return n_agents * BYTES_PER_AGENT_TICK * rows


class EveryNth:
    """Rows to `out`, tick rows only at k % every == 0 and the last tick (`finish`); the rest passes through."""

    def __init__(self, out: Rows, every: int) -> None:
        if every < 1:
            raise ValueError("every must be >= 1")
        self.out, self.every = out, every
        self._gaps = (math.inf, math.inf)  # smallest agent and obstacle gaps since the last written row
        self._held: tuple[Any, ...] | None = None  # the latest tick not written

    def tick(self, k: int, t: float, p: Array, theta: Array, alive: NDArray[np.bool_], max_error_m: float,
             min_agent_gap_m: float, min_obstacle_gap_m: float, groups: int) -> None:
        ga, go = self._gaps
        ga, go = _lesser(ga, min_agent_gap_m), _lesser(go, min_obstacle_gap_m)
        if k % self.every == 0:
            self._held = None
            self._gaps = (math.inf, math.inf)
            self.out.tick(k, t, p, theta, alive, max_error_m, ga, go, groups)
        else:
            self._gaps = (ga, go)
            self._held = (k, t, p.copy(), theta.copy(), alive.copy(), max_error_m, ga, go, groups)

    def finish(self) -> None:
        """Write the last tick if it was held back (call once the run ends, before closing the record)."""
        if self._held is not None:
            self.out.tick(*self._held)
            self._held = None

    def event(self, ev: Event) -> None:
        self.out.event(ev)

    def episode(self, e: Episode) -> None:
        self.out.episode(e)

    def episode_end(self, key: tuple[str, str, str], t: float) -> None:
        self.out.episode_end(key, t)


def _lesser(a: float, b: float) -> float:
    """min(a, b) where NaN (unknown) loses to any number."""
    if math.isnan(b):
        return a
    return b if math.isnan(a) or b < a else a
