"""The monitor's node (monitor/node.py) driven by hand, as its process drives it: inputs in, each output handled
as the port handles it (events recorded then kept as published, rows written to a real run.db with the same
`monitor.rows.write`, refused ends and the exit kept). No zenoh, no clock: times are given."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from monitor.messages import ClockFrom, Input, RefusedEnd, Scene
from monitor.node import MonitorNode
from monitor.rows import Resume, write
from reconswarm.net.node import Exit, Role, Stop, Token
from reconswarm.net.timing import Timing
from reconswarm.net.wire import wire
from reconswarm.net.wire.report import Report, Row
from reconswarm.paper.events import Event
from reconswarm.record.store import RunRecord, RunWriter
from reconswarm.scenario.model import load
from tests.support import PAPER

T = Timing(burst_s=1.0, end_grace_s=3.0, commit_sim_s=0.5, commit_wall_s=0.5, world_stall_s=2.0)
S = load(PAPER)
IDS = [a.id for a in S.agents]
DT = S.meta.dt_s
WORLD = "world-zid"  # the world's session (the clock's source)


def truth(k: int, p: np.ndarray | None = None, ids: list[int] | None = None) -> wire.Truth:
    p = S.starts if p is None else p
    return wire.Truth(k, k * DT, tuple(ids or IDS), tuple(p[:, 0]), tuple(p[:, 1]), tuple(S.headings),
                      tuple(p[:, 0]), tuple(p[:, 1]))


def clock(k: int, end: bool = False, reason: str = "converged", stats: dict[str, float] | None = None,
          source: str = WORLD) -> ClockFrom:
    c = wire.Clock(k, k * DT, tuple(IDS), wire.ClockMode.LOCKSTEP, 0.0, end, reason if end else "", 0,
                   stats if stats is not None else {})
    return ClockFrom(c, source)


def report(aid: int, rejected: int = 0, guessed_k: int = -1) -> Report:
    """An agent's heartbeat with its counters."""
    return Report(f"agent-{aid}", None, rejected, guessed_k)


def world_report(rows: tuple[Row, ...]) -> Report:
    return Report("simworld", rows)


def token(aid: int, up: bool) -> Token:
    return Token(Role.AGENT, up, aid)


def tokens(up: bool, ids: list[int] | None = None) -> list[Token]:
    return [token(a, up) for a in (IDS if ids is None else ids)]


def world(up: bool) -> Token:
    return Token(Role.WORLD, up)


class Run:
    """A node and its record, stepped by hand."""

    def __init__(self, tmp_path: Path, offset: float = 1000.0, append: bool = False) -> None:
        self.path = tmp_path / "run.db"
        self.writer = RunWriter(self.path, S, "lockstep", append=append)
        resume = Resume.of(self.writer) if append else None
        self.node = MonitorNode(S, resume, T, unix_offset_s=offset)
        self.events: list[Event] = []  # published, in order
        self.refused: list[RefusedEnd] = []
        self.rows: list[Any] = []  # what went to the record (events included), in order
        self.exit: Exit | None = None
        self.scenes: list[Scene] = []  # what the live views were given, in order

    def step(self, now: float, *inputs: Input) -> list[Event]:
        """One step; the events it published."""
        assert self.exit is None, "stepped after its exit"
        new = []
        for out in self.node.step(list(inputs), now):
            if isinstance(out, Exit):
                self.exit = out
            elif isinstance(out, RefusedEnd):
                self.refused.append(out)
            elif isinstance(out, Scene):  # (for the live views)
                self.scenes.append(out)
            else:
                self.rows.append(out)
                write(self.writer, out)
                if isinstance(out, Event):
                    new.append(out)
        self.events += new
        return new

    def tick(self, k: int, now: float, p: np.ndarray | None = None, quiet: tuple[int, ...] = ()) -> list[Event]:
        """The world's clock and truth of tick k, and the reports (heartbeats) of every agent not quiet."""
        return self.step(now, clock(k), truth(k, p), *(report(a) for a in IDS if a not in quiet))

    def stop(self, now: float, *inputs: Input) -> list[Event]:
        got = self.step(now, Stop(), *inputs)
        assert self.exit is not None and self.exit.code == 0
        return got

    def record(self) -> RunRecord:
        return RunRecord(self.path)


def started(tmp_path: Path, offset: float = 1000.0) -> Run:
    """A run whose agents' tokens are all there (the first tokens are not joins)."""
    run = Run(tmp_path, offset)
    assert run.step(0.0, *tokens(True)) == []
    return run


def kinds(events: list[Event]) -> list[tuple[str, int | None]]:
    return [(e.kind.value, e.agent) for e in events]
