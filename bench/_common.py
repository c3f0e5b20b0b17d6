"""Shared bits of the benchmark scripts: medians, the machine's load, scenario helpers."""

from __future__ import annotations

import dataclasses
import os
import platform
import statistics
import sys
from collections.abc import Sequence

from reconswarm.scenario.model import Scenario


def median(xs: Sequence[float]) -> float:
    return float(statistics.median(xs))


def fmt_list(xs: Sequence[float], digits: int = 3) -> str:
    return "[" + ", ".join(f"{x:.{digits}f}" for x in xs) + "]"


def machine() -> str:
    """One line about where the figures come from: CPU count and load (the machine may be shared)."""
    try:
        load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:  # pragma: no cover - not on every platform
        load = "n/a"
    return (f"python {platform.python_version()} on {platform.machine()}, {os.cpu_count()} CPUs, "
            f"load average {load}")


def command_line() -> str:
    exe = os.path.relpath(sys.executable)
    return " ".join([sys.executable if exe.startswith("..") else exe, *sys.argv])


def with_ticks(s: Scenario, ticks: int) -> Scenario:
    """The scenario cut to a fixed number of steps (ticks + 1 ticks are run, 0..ticks)."""
    return dataclasses.replace(s, meta=dataclasses.replace(s.meta, duration_s=ticks * s.meta.dt_s))
