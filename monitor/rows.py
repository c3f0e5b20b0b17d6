"""The monitor's rows for the record: what its node (monitor/node.py) returns for run.db, and how its process
writes them (`write`, on `store.RunWriter`).

The node owns no writer: it returns these rows in the order the record takes them, its process hands each to the
record as it comes (a full disk is the process's: exit 3). The events are outputs of their own (an `Event` is
recorded, then published on the event key: the same object). The schema is the record's, unchanged
(reconswarm/record/store.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from reconswarm.net.wire.report import Row
from reconswarm.paper.events import Event
from reconswarm.record.safety import Episode
from reconswarm.record.store import RunWriter

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Meta:
    """Meta values to set now (`mode`, `mission_start_unix`), as the record keeps them (text)."""

    items: tuple[tuple[str, str], ...]


@dataclass(frozen=True, eq=False)
class TickRow:
    """One recorded tick: the arrays are the node's copies, in scenario order."""

    k: int
    t_s: float
    p: Array
    theta: Array
    alive: NDArray[np.bool_]
    max_error_m: float
    min_agent_gap_m: float
    min_obstacle_gap_m: float
    groups: int


@dataclass(frozen=True)
class EpisodeStart:
    """A collision or safety episode began (the contacts table)."""

    episode: Episode


@dataclass(frozen=True)
class EpisodeEnd:
    """The open episode of (kind, a, b) ended at t_s."""

    key: tuple[str, str, str]
    t_s: float


@dataclass(frozen=True)
class Gap:
    """Ticks between t_from_s and t_to_s are not in the record, and why."""

    t_from_s: float
    t_to_s: float
    note: str


@dataclass(frozen=True)
class Counters:
    """Messages rejected so far, per process (`monitor`, `simworld`, `agent <id>`): replaces earlier rows."""

    counts: tuple[tuple[str, int], ...]


@dataclass(frozen=True)
class Intrusions:
    """Another process's whole tally of refused messages, from its report: replaces its earlier rows."""

    process: str
    rows: tuple[Row, ...]


@dataclass(frozen=True)
class Commit:
    """A commit point: everything recorded up to simulated time t_s must be on disk now (a killed monitor
    loses at most `commit_sim_s` of the run)."""

    t_s: float


@dataclass(frozen=True)
class Close:
    """The final summary: the record's `extra` (end reason, the world's end statistics, `deterministic`),
    whether the mission finished, its wall time (None: the mission never started) and mode; then the
    record is closed."""

    extra: dict[str, Any] = field(hash=False)
    finished: bool
    wall_time_s: float | None
    mode: str | None


@dataclass(frozen=True)
class Resume:
    """A record this monitor appends to (a restarted monitor): its last tick, and the mission's start as the
    first monitor recorded it (None: not recorded)."""

    k: int
    t_s: float
    mission_start_unix: float | None

    @staticmethod
    def of(w: RunWriter) -> Resume | None:
        """Where an existing record stands (None: it holds no tick yet)."""
        last = w.last_tick()
        if last is None:
            return None
        start = w.get_meta("mission_start_unix")
        return Resume(last[0], last[1], None if start is None else float(start))


Record = Meta | TickRow | EpisodeStart | EpisodeEnd | Gap | Counters | Intrusions | Commit | Close


class RowSink:
    """What the node's recorder (record/recorder.Recorder) writes, collected as outputs in order: its events
    (recorded, then published) and rows."""

    def __init__(self) -> None:
        self.out: list[Any] = []  # (the node's outputs: these, and its own)

    def tick(self, k: int, t: float, p: Array, theta: Array, alive: NDArray[np.bool_], max_error_m: float,
             min_agent_gap_m: float, min_obstacle_gap_m: float, groups: int) -> None:
        self.out.append(TickRow(k, t, p.copy(), theta.copy(), alive.copy(), max_error_m, min_agent_gap_m,
                                min_obstacle_gap_m, groups))

    def event(self, ev: Event) -> None:
        self.out.append(ev)

    def episode(self, e: Episode) -> None:
        self.out.append(EpisodeStart(e))

    def episode_end(self, key: tuple[str, str, str], t: float) -> None:
        self.out.append(EpisodeEnd(key, t))


def write(w: RunWriter, row: Record | Event) -> None:
    """Hand one of the node's rows (or events) to the record."""
    if isinstance(row, TickRow):
        w.tick(row.k, row.t_s, row.p, row.theta, row.alive, row.max_error_m, row.min_agent_gap_m,
               row.min_obstacle_gap_m, row.groups)
    elif isinstance(row, Event):
        w.event(row)
    elif isinstance(row, EpisodeStart):
        w.episode(row.episode)
    elif isinstance(row, EpisodeEnd):
        w.episode_end(row.key, row.t_s)
    elif isinstance(row, Gap):
        w.note_gap(row.t_from_s, row.t_to_s, row.note)
    elif isinstance(row, Meta):
        w.set_meta(**dict(row.items))
    elif isinstance(row, Counters):
        w.counters(dict(row.counts))
    elif isinstance(row, Intrusions):
        w.intrusions(row.process, list(row.rows))
    elif isinstance(row, Commit):
        w.commit()
    elif isinstance(row, Close):
        meta: dict[str, Any] = {"extra": row.extra, "finished": "1" if row.finished else "0"}
        if row.wall_time_s is not None:
            meta["wall_time_s"] = f"{row.wall_time_s:.6f}"
        if row.mode:
            meta["mode"] = row.mode
        w.close(**meta)
