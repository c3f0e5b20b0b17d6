"""What a run record's `extra` may add to the summary, and what the world's end statistics may add to `extra`.

The summary's fields are computed from the record (reconswarm/record/summary.py); `extra` adds only the
fields named here, each checked for its type and range, and never one the summary computes. The world's end
statistics travel on the wire (its end clock's `stats`): an end stamped with the world's session id is
believed as an end, but its statistics are only the world's counters below (docs/wire.md#run-summary).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

# The world's end statistics: name -> kind. count: a whole number >= 0; ms, s: a finite number >= 0;
# ratio: a finite number in [0, 1].
WORLD_STATS: dict[str, str] = {
    "world_overruns": "count",
    "latency_p50_ms": "ms",
    "latency_p99_ms": "ms",
    "latency_samples": "count",
    "missed_deadlines": "count",
    "deadlines": "count",
    "missed_deadline_ratio": "ratio",
    "uncommanded_from_s": "s",  # (the monitor's: it takes it into `deterministic`, the summary never shows it)
}

# Why the world ends a mission (its end clock's `reason`), and every end reason a record may hold (a launcher's
# note: `timeout`; the monitor's: `world lost`).
WORLD_END_REASONS = ("converged", "duration", "no agents", "stopped")
END_REASONS = (*WORLD_END_REASONS, "timeout", "world lost")

# What the record's writers (the monitor, the in-process engine, a launcher's note) put in `extra` themselves.
OWN: dict[str, str] = {
    "end_reason": "reason",
    "deterministic": "bool",
    "determinism_lost_at_s": "s?",
    "stalls": "count",
    "agent_steps_per_s": "s?",
    "mission_cpu_s": "s",  # (the in-process engine's mission loop, CPU seconds)
}


def _check(kind: str, v: Any) -> tuple[bool, Any]:
    """(whether v is of this kind, v as the summary shows it)."""
    if kind == "reason":
        return v in END_REASONS, v
    if kind == "bool":
        return isinstance(v, bool), v
    if kind.endswith("?") and v is None:
        return True, None
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
        return False, None
    if kind == "count":
        return float(v).is_integer() and v < 2**53, int(v)
    if kind == "ratio":
        return v <= 1.0, float(v)
    return True, float(v) if isinstance(v, float) else v


def world_stats(raw: Mapping[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """The world's end statistics that are its counters, checked: (those kept, the names of those dropped)."""
    kept: dict[str, Any] = {}
    dropped: list[str] = []
    for key, v in raw.items():
        ok, val = _check(WORLD_STATS[key], v) if key in WORLD_STATS else (False, None)
        if ok:
            kept[key] = val
        else:
            dropped.append(key)
    return kept, dropped


def trusted(extra: Mapping[str, Any], computed: Mapping[str, Any]) -> dict[str, Any]:
    """What the summary takes from a record's `extra`: the writers' own fields and the world's counters, each of
    its kind, never a field in `computed` other than the ones the monitor decides (`deterministic`,
    `determinism_lost_at_s`); `uncommanded_from_s` is the monitor's input, not shown."""
    out: dict[str, Any] = {}
    for key, v in extra.items():
        kind = OWN.get(key) or (WORLD_STATS.get(key) if key != "uncommanded_from_s" else None)
        if kind is None or (key in computed and key not in OWN):
            continue
        ok, val = _check(kind, v)
        if ok:
            out[key] = val
    return out
