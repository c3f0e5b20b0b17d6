"""`monitor export --format mcap`: a run record as an MCAP file for Foxglove (channels in monitor/scene.py).

Written with the Foxglove SDK on a private Context (so nothing else in the process logs into the file);
message times are the run's wall-clock start plus simulated time. The scenario TOML is attached and the
run's summary is the file's `run` metadata.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import foxglove
import numpy as np

from monitor import scene
from reconswarm.errors import BadInput
from reconswarm.record.store import RunRecord
from reconswarm.record.summary import summarize

AGENT_SCENES_BUDGET = 500_000  # agents drawn over the whole file (~70 bytes each compressed: ~35 MB)
PERIODS_S = (0.1, 0.2, 0.5, 1.0)  # the sampling periods tried, in order, when every tick is over budget


@dataclass(frozen=True)
class ExportStats:
    path: Path
    bytes: int
    scene_messages: int
    period_s: float | None  # None: every tick
    events: int


def choose_period(n_agents: int, t: np.ndarray, period_s: float | None) -> float | None:
    """The scene's sampling period: the caller's (0 < period <= 1 s); else every tick if the agents drawn
    stay within AGENT_SCENES_BUDGET (the paper run: 10 x 4446), else the first of PERIODS_S that does,
    else 1 s (at least one scene per simulated second, whatever the size)."""
    if period_s is not None:
        if not (0.0 < period_s <= 1.0):
            raise BadInput(f"--period: {period_s} s is not in (0, 1] (at least one scene per simulated second)")
        return period_s
    if n_agents * t.size <= AGENT_SCENES_BUDGET:
        return None
    for p in PERIODS_S:
        if n_agents * sampled_rows(t, p).size <= AGENT_SCENES_BUDGET:
            return p
    return PERIODS_S[-1]


def sampled_rows(t: np.ndarray, period_s: float | None) -> np.ndarray:
    """Indices of the ticks drawn: all, or the first tick of every period (t >= 0, sorted)."""
    if period_s is None or t.size == 0:
        return np.arange(t.size)
    bucket = np.floor(t / period_s + 1e-9)
    return np.flatnonzero(np.concatenate(([True], bucket[1:] != bucket[:-1])))


def _time_base(rec: RunRecord, t_end: float) -> tuple[int, str]:
    started = rec.meta.get("started_unix")
    if started is not None:
        try:
            return scene.start_ns(started), "started_unix"
        except ValueError:
            pass
    # A record without its start: the file's last change is about the end of the run.
    return round((os.path.getmtime(rec.path) - t_end) * 1e9), "record file mtime - duration"


def _metadata(rec: RunRecord, summary: dict[str, Any], start: int, base: str) -> dict[str, str]:
    out = {k: ("" if v is None else v if isinstance(v, str) else json.dumps(v)) for k, v in summary.items()}
    out.update(started_unix=rec.meta.get("started_unix", ""), start_time_ns=str(start), time_base=base,
               scenario_source=rec.meta.get("scenario_source", ""), record=str(rec.path),
               record_schema=rec.meta.get("schema", ""))
    return out


def _check_output(out: Path) -> None:
    parent = out.parent if str(out.parent) else Path(".")
    if out.is_dir():
        raise BadInput(f"{out}: is a directory")
    if not parent.is_dir():
        raise BadInput(f"{out}: cannot write (no directory {parent})")
    if not os.access(parent, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise BadInput(f"{out}: cannot write (permission denied)")


def export_mcap(rec: RunRecord, out: Path, period_s: float | None = None,
                progress: Callable[[int, int], None] | None = None) -> ExportStats:
    """Write rec as MCAP to out (replaced if it exists). progress(done, total) is called now and then."""
    _check_output(out)
    s = rec.scenario
    tk = rec.ticks()
    if tk.t.size == 0:
        raise BadInput(f"{rec.path}: the record holds no ticks yet")
    events = rec.events()
    summary = summarize(rec)
    ids, radii = rec.ids, s.radii
    period = choose_period(len(ids), tk.t, period_s)
    drawn = np.zeros(tk.t.size, dtype=bool)
    drawn[sampled_rows(tk.t, period)] = True
    start, base = _time_base(rec, float(tk.t[-1]))

    ctx = foxglove.Context()
    try:
        writer = foxglove.open_mcap(out, allow_overwrite=True, context=ctx)
    except Exception as exc:  # the SDK's own error type for I/O failures
        raise BadInput(f"{out}: cannot write ({exc})") from None
    scene_messages = 0
    try:
        channels = scene.SceneChannels(ctx, s, ids)
        writer.write_metadata("run", _metadata(rec, summary, start, base))
        writer.attach(log_time=start, create_time=start, name="scenario.toml", media_type="application/toml",
                      data=rec.meta["scenario_toml"].encode())
        graph = scene.SwarmGraph(s.planner.link_range_m)
        ev = 0
        for row in range(tk.t.size):
            t = float(tk.t[row])
            p = np.stack([tk.px[row], tk.py[row]], axis=1)
            links, group = graph.step(p, tk.alive[row])  # every tick: the links' hysteresis needs each one
            while ev < len(events) and float(events[ev]["t"]) <= t:
                channels.event(events[ev], scene.stamp_ns(start, float(events[ev]["t"])))
                ev += 1
            if not drawn[row]:
                continue
            frame = scene.SwarmFrame(t, ids, p, tk.theta[row], tk.alive[row], radii, group, links)
            channels.tick(frame, scene.stamp_ns(start, t), float(tk.max_error_m[row]),
                          float(tk.min_agent_gap_m[row]), float(tk.min_obstacle_gap_m[row]))
            scene_messages += 1
            if progress is not None and scene_messages % 100 == 0:
                progress(row + 1, int(tk.t.size))
        for e in events[ev:]:  # events after the last tick (a run stopped right after one)
            channels.event(e, scene.stamp_ns(start, float(e["t"])))
    finally:
        writer.close()
    if progress is not None:
        progress(int(tk.t.size), int(tk.t.size))
    return ExportStats(out, out.stat().st_size, scene_messages, period, len(events))
