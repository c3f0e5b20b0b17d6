"""The monitor's logic as a pure state machine: no zenoh, no clock of its own.

`MonitorNode` takes decoded messages (the world's clock and truth, the agents' reports, liveliness
changes) with the time `now_s` it is told, records the run through the `Recorder` (the same as the
in-process engine) and collects every event it records in `outbox`, which the zenoh adapter
(monitor/process.py) publishes on `swarm/<run>/event`: one code path, record then publish, the same
`Event` object, so the record and the wire cannot disagree.

Membership: an agent's token that disappears is `agent_lost`, one that comes back `agent_joined`;
several lost within `burst_s` while others stay is the network splitting (a `split`, cause
"network"), their return a `merge`. The world: its clock silent for `world_stall_s` (or its token
gone) is a stall; while it lasts, agents' tokens that come and go are not their fault (they reconnect
when nothing moves) and are only judged `burst_s` after the world is back; the stall is recorded as
one `world_stalled` event (with its wall duration), ticks that never arrived as a `gaps` row, and a
world that never comes back as `world_lost` when the monitor finishes.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from reconswarm.net import wire
from reconswarm.net.keys import WireError
from reconswarm.net.timing import TIMING, Timing
from reconswarm.paper.events import Event, EventKind, Groups
from reconswarm.record.recorder import Recorder
from reconswarm.record.store import RunWriter
from reconswarm.scenario.model import Scenario

log = logging.getLogger("reconswarm.monitor")


def _g(*groups: list[int]) -> Groups:
    return tuple(tuple(g) for g in groups)


class MonitorNode:
    def __init__(self, s: Scenario, writer: RunWriter, resume_from: tuple[int, float] | None = None,
                 timing: Timing = TIMING, unix_offset_s: float = 0.0) -> None:
        """resume_from: (k, t) of the last tick of a record this monitor appends to; unix_offset_s: Unix time
        minus the `now_s` clock (to stamp `wall_unix` without a clock of its own)."""
        self.s, self.writer, self.timing, self.unix_offset_s = s, writer, timing, unix_offset_s
        self.ids = [a.id for a in s.agents]
        self.index = {a: k for k, a in enumerate(self.ids)}
        n = len(self.ids)
        self.resume_from = resume_from
        self.rec = Recorder(s, writer)
        self.outbox: list[Event] = []  # recorded, not yet published
        self.counts: dict[str, int] = {}  # messages rejected per process (from the clock and the reports)
        self.p = s.starts.copy()
        self.theta = s.headings.copy()
        self.pending: dict[int, wire.Truth] = {}
        self.written = resume_from[0] if resume_from else -1
        self.t = resume_from[1] if resume_from else 0.0
        self.committed_t = self.t
        self.alive = np.zeros(n, dtype=bool)
        self.seen = np.zeros(n, dtype=bool)
        self.end: wire.Clock | None = None  # the end claimed by an admitted clock, until refused (see poll)
        self.end_at = 0.0
        self.end_source = ""
        self.world_gone_at: float | None = None  # the world's token went (after a claimed end: the world's own)
        self.refused_ends: list[tuple[str, str]] = []  # (source, why) of ends refused, for the adapter to count
        self.conflict_t: float | None = None  # first conflicting command a process reported (simulated s)
        self.mode: str | None = None
        self.guessed_k = -1  # the first tick an agent acted on without all its data (lockstep; -1: none)
        self.wall0: float | None = None  # when the first clock came
        self.min_gap = float("inf")
        self.burst_lost: list[int] = []  # agents lost in the current burst (network split detection)
        self.burst_lost_at = self.burst_lost_t = 0.0
        self.burst_before: list[int] = []
        self.burst_back: list[int] = []
        self.burst_back_at = self.burst_back_t = 0.0
        self.partitioned: set[int] = set()
        self.last_clock_s = 0.0
        self.stall_since: float | None = None  # wall time the world's stall began
        self.stall_t = 0.0
        self.judge_at: float | None = None  # after a stall: when to judge the tokens that changed meanwhile
        self.deferred: dict[int, bool] = {}  # agent -> its token's latest state, seen during a stall

    # ------------------------------------------------------------------------------------- events

    def emit(self, ev: Event) -> None:
        """Record, then queue for publishing: the same object."""
        self.rec.event(ev)
        self.outbox.append(ev)

    def take_events(self) -> list[Event]:
        out, self.outbox = self.outbox, []
        return out

    def _wall(self, now_s: float) -> float:
        return round(now_s + self.unix_offset_s, 6)

    def _alive_ids(self) -> list[int]:
        return [int(a) for a in np.array(self.ids)[self.alive]]

    # ------------------------------------------------------------------------------------- membership

    def agent_up(self, aid: int, up: bool, now_s: float) -> None:
        if aid not in self.index or self.end is not None:  # agents leave when the mission ends: not a loss
            return
        if self.stall_since is not None or self.judge_at is not None:
            self.deferred[aid] = up
            return
        self.membership(aid, up, now_s)

    def membership(self, aid: int, up: bool, now_s: float) -> None:
        i = self.index[aid]
        before = self._alive_ids()
        if not up and self.alive[i]:
            if not self.burst_lost:
                self.burst_lost_at, self.burst_lost_t, self.burst_before = now_s, self.t, before
            self.burst_lost.append(aid)
        elif up and not self.alive[i] and aid in self.partitioned:
            if not self.burst_back:
                self.burst_back_at, self.burst_back_t = now_s, self.t
            self.burst_back.append(aid)
        was = bool(self.alive[i])
        self.alive[i] = up
        after = self._alive_ids()
        if up and not was and self.seen[i]:
            self.emit(Event(round(self.t, 9), EventKind.AGENT_JOINED, _g(before), _g(after), agent=aid,
                            wall_unix=self._wall(now_s)))
            log.info("agent %d joined at t=%.2f", aid, self.t)
        elif not up and was:
            self.emit(Event(round(self.t, 9), EventKind.AGENT_LOST, _g(before), _g(after), agent=aid,
                            wall_unix=self._wall(now_s)))
            log.warning("agent %d lost at t=%.2f", aid, self.t)
        self.seen[i] |= up

    def network_events(self, now_s: float) -> None:
        """Several agents lost together while others stay is the swarm's network splitting: record a split
        (cause "network"); their return, a merge. Single losses stay agent_lost / agent_joined only."""
        alive = self._alive_ids()
        if self.burst_lost and now_s - self.burst_lost_at >= self.timing.burst_s:
            lost = sorted(a for a in set(self.burst_lost) if not self.alive[self.index[a]])
            if len(lost) >= 2 and alive:
                self.emit(Event(round(self.burst_lost_t, 9), EventKind.SPLIT, _g(self.burst_before),
                                _g(*sorted([alive, lost], key=lambda g: g[0])), cause="network",
                                wall_unix=self._wall(now_s)))
                self.partitioned |= set(lost)
            self.burst_lost = []
        if self.burst_back and now_s - self.burst_back_at >= self.timing.burst_s:
            back = sorted(a for a in set(self.burst_back) if self.alive[self.index[a]])
            rest = [a for a in alive if a not in back]
            if back and rest:
                groups = _g(*sorted([rest, back], key=lambda g: g[0]))
                self.emit(Event(round(self.burst_back_t, 9), EventKind.MERGE, groups, _g(alive), cause="network",
                                wall_unix=self._wall(now_s)))
            self.partitioned -= set(back)
            self.burst_back = []

    # ------------------------------------------------------------------------------------- the world

    def world_up(self, up: bool, now_s: float) -> None:
        self.world_gone_at = None if up else now_s
        if not up and self.wall0 is not None and self.end is None:
            self._stalled(now_s, "its token is gone")

    def _stalled(self, now_s: float, why: str) -> None:
        if self.stall_since is None:
            self.stall_since, self.stall_t = self.last_clock_s, self.t  # since the world was last heard
            log.warning("the world stalls at t=%.2f (%s): agents' tokens are not judged until it is back", self.t,
                        why)

    def refuse_end(self, why: str) -> None:
        """The end claimed is not the world's: refused (counted by the adapter with its source), recording goes on."""
        assert self.end is not None
        log.warning("an end at t=%.2f (%s) refused: %s", self.end.t, self.end.reason, why)
        self.refused_ends.append((self.end_source, f"end {self.end.reason!r} at tick {self.end.k}: {why}"))
        self.end = None

    def clock(self, c: wire.Clock, now_s: float, source: str = "") -> None:
        if self.end is not None and not c.end and c.k >= self.end.k:  # the world ticks on: it did not end
            self.refuse_end(f"the world's clock goes on (tick {c.k})")
        self.last_clock_s = now_s
        if self.stall_since is not None:
            self.emit(Event(round(self.stall_t, 9), EventKind.WORLD_STALLED,
                            duration_s=round(now_s - self.stall_since, 3), wall_unix=self._wall(now_s)))
            log.warning("the world is back after %.1f s", now_s - self.stall_since)
            self.stall_since, self.judge_at = None, now_s + self.timing.burst_s
        self.t = max(self.t, c.t)
        if self.mode != c.mode:
            self.writer.set_meta(mode=str(c.mode))
        self.mode = str(c.mode)
        self.counts["simworld"] = c.rejected
        if self.wall0 is None:
            self.wall0 = now_s
            if self.resume_from is None:
                self.writer.set_meta(mission_start_unix=f"{now_s + self.unix_offset_s:.6f}")
        if c.end and self.end is None:
            self.end, self.end_at, self.end_source = c, now_s, source

    def _judge_deferred(self, now_s: float) -> None:
        """A stall is over: tokens that are down now (and were up) are losses; ones that flapped are not."""
        for aid, up in sorted(self.deferred.items()):
            if up != bool(self.alive[self.index[aid]]):
                self.membership(aid, up, now_s)
        self.deferred, self.judge_at = {}, None

    # ------------------------------------------------------------------------------------- data

    def truth(self, tr: wire.Truth) -> None:
        if any(a not in self.index for a in tr.ids):
            raise WireError("truth names an agent that is not in the scenario")
        if tr.k > self.written:
            self.pending[tr.k] = tr

    def conflict(self, first_t: float) -> None:
        """A process refused a conflicting command (two different commands for one agent's tick): the run is no
        longer the in-process engine's, whatever else happened."""
        if self.conflict_t is None:
            log.warning("conflicting commands at t=%.2f: the run is not deterministic", first_t)
        self.conflict_t = first_t if self.conflict_t is None else min(self.conflict_t, first_t)

    def telemetry(self, agent_id: int, rejected: int, guessed_k: int) -> None:
        """An agent's counters (from its report): messages it rejected, the first tick it guessed (-1: none)."""
        if agent_id not in self.index:
            raise WireError(f"agent {agent_id} is not in the scenario")
        self.counts[f"agent {agent_id}"] = rejected
        if guessed_k >= 0 and (self.guessed_k < 0 or guessed_k < self.guessed_k):
            if self.guessed_k < 0:
                log.warning("agent %d acted on tick %d without all its data: lockstep is no longer deterministic",
                            agent_id, guessed_k)
            self.guessed_k = guessed_k

    def flush(self) -> None:
        """Write the ticks received, in order; ticks that never came are a gap in the record."""
        dt = self.s.meta.dt_s
        while self.pending:
            k = min(self.pending)
            tr = self.pending.pop(k)
            for aid, px, py, th in zip(tr.ids, tr.px, tr.py, tr.theta, strict=True):
                i = self.index[aid]
                self.p[i] = (px, py)
                self.theta[i] = th
            t = k * dt
            if self.resume_from is not None and self.written == self.resume_from[0]:
                self.writer.note_gap(self.resume_from[1], t, "monitor restarted: ticks in between not recorded")
                self.rec.topology.confirmed = None  # a fresh start: no events across the gap
            elif self.written >= 0 and k > self.written + 1:
                self.writer.note_gap(self.written * dt, t, f"ticks {self.written + 1}..{k - 1} never received")
                log.warning("ticks %d..%d never received: noted as a gap in the record", self.written + 1, k - 1)
            for ev in self.rec.tick(k, t, self.p, self.theta, self.alive.copy()):
                self.outbox.append(ev)  # recorded by the recorder: publish the same object
            self.written, self.t = k, t
            self.min_gap = min(self.min_gap, self.rec.safety.min_agent_gap_m)
            if t - self.committed_t >= self.timing.commit_sim_s:  # a killed monitor loses at most this much
                self.writer.commit()
                self.committed_t = t

    def poll(self, now_s: float) -> bool:
        """Write what came, detect bursts and stalls; True once the mission's end is recorded."""
        self.flush()
        if self.end is None:
            if self.wall0 is not None and now_s - self.last_clock_s >= self.timing.world_stall_s:
                self._stalled(now_s, f"no clock for {now_s - self.last_clock_s:.1f} s")
            if self.judge_at is not None and now_s >= self.judge_at and self.stall_since is None:
                self._judge_deferred(now_s)
            self.network_events(now_s)
            return False
        # A claimed end stands once its tick is recorded and the world is gone (it closes its session after its
        # end: a forger's clock is followed by the world's), or after end_grace_s; the truth must not contradict
        # it: "converged" is refused unless the record's own error says so at its tick (or, its tick never come,
        # at the last one recorded, which the summary will judge).
        gone = self.world_gone_at is not None and self.world_gone_at >= self.end_at
        late = now_s - self.end_at > self.timing.end_grace_s
        if (self.written >= self.end.k or late) and self.end_contradicted():
            return False
        return (self.written >= self.end.k and gone) or late

    def end_contradicted(self) -> bool:
        """A claimed "converged" that the record's truth contradicts is refused (True)."""
        if self.end is None or self.end.reason != "converged" or self.rec.converged():
            return False
        self.refuse_end(f"the truth is not converged (max |e| {self.rec.max_error_m:.3g} m at tick {self.written})")
        return True

    def finish(self, now_s: float, rejected_here: int) -> None:
        """Close the record: counters, the end reason (or the world's loss), the wall time."""
        self.counts["monitor"] = rejected_here
        self.writer.counters(self.counts)
        extra: dict[str, Any] = {}
        if self.end is not None:
            extra = dict(self.end.stats)
            extra["end_reason"] = self.end.reason
        elif self.stall_since is not None:
            self.emit(Event(round(self.stall_t, 9), EventKind.WORLD_LOST,
                            duration_s=round(now_s - self.stall_since, 3), wall_unix=self._wall(now_s)))
            extra["end_reason"] = "world lost"
            if self.deferred:
                log.info("not judged (the world was lost): tokens of agents %s", sorted(self.deferred))
        # Lockstep equals the in-process engine unless an agent had to act without all of a tick's data, or the
        # world stepped a robot without that tick's command (its end statistics say the first such tick).
        # A conflicting command (someone else spoke for an agent) loses it too.
        uncommanded = extra.pop("uncommanded_from_s", None)
        lost = [t for t in (self.guessed_k * self.s.meta.dt_s if self.guessed_k >= 0 else None, self.conflict_t,
                            uncommanded) if t is not None]
        extra["deterministic"] = self.mode == "lockstep" and not lost
        extra["determinism_lost_at_s"] = round(min(lost), 9) if lost else None
        finished = self.end is not None and self.end.reason != "stopped"  # (stopped: the mission was cut short)
        meta: dict[str, Any] = {"extra": extra, "finished": "1" if finished else "0"}
        start = self.writer.get_meta("mission_start_unix")
        if start is not None:  # from the first clock, whichever monitor incarnation saw it
            meta["wall_time_s"] = f"{now_s + self.unix_offset_s - float(start):.6f}"
        if self.mode:
            meta["mode"] = self.mode
        self.writer.close(**meta)
