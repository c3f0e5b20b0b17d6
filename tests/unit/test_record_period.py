"""Record decimation (reconswarm/record/decimate.py): tick rows every `every` ticks and the last one, each row
carrying the smallest gaps since the row before it; events and episodes pass through."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from reconswarm.record.decimate import BYTES_PER_AGENT_TICK, EveryNth, record_bytes


class Collect:
    def __init__(self) -> None:
        self.ticks: list[tuple[int, float, float, float]] = []
        self.other: list[object] = []

    def tick(self, k, t, p, theta, alive, max_error_m, min_agent_gap_m, min_obstacle_gap_m, groups) -> None:
        self.ticks.append((k, float(p[0, 0]), min_agent_gap_m, min_obstacle_gap_m))

    def event(self, ev) -> None:
        self.other.append(ev)

    def episode(self, e) -> None:
        self.other.append(e)

    def episode_end(self, key, t) -> None:
        self.other.append((key, t))


def feed(every: int, n_ticks: int, gaps: list[float]) -> Collect:
    out = Collect()
    w = EveryNth(out, every)
    for k in range(n_ticks):
        p = np.full((2, 2), float(k))
        w.tick(k, 0.05 * k, p, np.zeros(2), np.ones(2, dtype=bool), 1.0, gaps[k], gaps[k] + 100, 1)
        p[:] = -1.0  # the caller's array changes after the call: a held row keeps its own copy
    w.finish()
    return out


def test_rows_every_nth_tick_and_the_last():
    out = feed(4, 10, [9.0] * 10)
    assert [r[0] for r in out.ticks] == [0, 4, 8, 9]
    assert [r[1] for r in out.ticks] == [0.0, 4.0, 8.0, 9.0]


def test_the_last_tick_on_a_row_is_written_once():
    assert [r[0] for r in feed(3, 7, [1.0] * 7).ticks] == [0, 3, 6]


def test_each_row_carries_the_smallest_gaps_since_the_row_before():
    gaps = [5.0, 4.0, 1.0, 6.0, 7.0, 8.0, 0.5, 9.0, math.nan]
    out = feed(4, 9, gaps)
    assert [(r[0], r[2], r[3]) for r in out.ticks] == [(0, 5.0, 105.0), (4, 1.0, 101.0), (8, 0.5, 100.5)]


def test_events_and_episodes_pass_through():
    out = Collect()
    w = EveryNth(out, 5)
    ev: Any = "ev"  # (stand-ins: the wrapper passes them on as they are)
    ep: Any = "ep"
    w.event(ev)
    w.episode(ep)
    w.episode_end(("a", "b", "c"), 1.0)
    assert out.other == ["ev", "ep", (("a", "b", "c"), 1.0)]
    with pytest.raises(ValueError):
        EveryNth(out, 0)


def test_the_size_of_a_record():
    assert BYTES_PER_AGENT_TICK == 25
    assert record_bytes(100_000, 101) == 252_500_000
