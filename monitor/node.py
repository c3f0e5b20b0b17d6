"""The monitor's logic as a pure state machine: no zenoh, no clock of its own, no writer.

`MonitorNode.step(inputs, now_s)` keeps the node contract (reconswarm/net/node.py; inputs and outputs in
monitor/messages.py): it takes the world's clock and truth, the other processes' reports and liveliness
tokens, and returns, in order, the events it recorded (the process records then publishes each on
`swarm/<run>/event`: one object, so the record and the wire cannot disagree), the rows for run.db
(monitor/rows.py, the same as the in-process engine's through the same `Recorder`), the ends it refused,
and `Exit` once the mission's end is recorded or it was told to stop.

Who is alive is decided once, by the node's `Presence` (monitor/presence.py): a token AND the agent's own
reports (its heartbeat); our own session losing its router is nobody's loss (`RouterReach`); losses, returns
and network splits are its events. The world: its clock silent for `world_stall_s` (or its token gone) is a
stall (a clock within `burst_s` of its token going was put before it went: not the world back); while it
lasts, agents that come and go are not judged (they reconnect when nothing moves) until `burst_s` after the
world is back; the stall is one `world_stalled` event (with its wall duration), ticks that
never arrived a `gaps` row, and a world that never comes back `world_lost` when the monitor finishes.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import Any

from monitor.messages import ClockFrom, Input, Output, RefusedEnd, Scene
from monitor.presence import Presence
from monitor.rows import Close, Commit, Counters, Gap, Intrusions, Meta, Resume, RowSink
from reconswarm.net.node import Exit, Invalid, Role, RouterReach, Stop, Token
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.trust.admission import IntrusionKind
from reconswarm.net.wire import wire
from reconswarm.net.wire.report import Report
from reconswarm.paper.events import Event, EventKind
from reconswarm.record.extra import WORLD_END_REASONS, world_stats
from reconswarm.record.recorder import Recorder
from reconswarm.scenario.model import Scenario

log = logging.getLogger("reconswarm.monitor")


class MonitorNode:
    def __init__(self, s: Scenario, resume: Resume | None = None, timing: Timing = TIMING,
                 unix_offset_s: float = 0.0) -> None:
        """resume: the record this monitor appends to; unix_offset_s: Unix time minus the `now_s` clock (to stamp
        `wall_unix` without a clock of its own)."""
        self.s, self.timing, self.unix_offset_s, self.resume = s, timing, unix_offset_s, resume
        self.ids = [a.id for a in s.agents]
        self.index = {a: k for k, a in enumerate(self.ids)}
        self.rows = RowSink()  # this step's outputs, in order (the recorder writes into it too)
        self.rec = Recorder(s, self.rows)
        self.presence = Presence(self.ids, timing, unix_offset_s)  # who is alive: decided there, once
        self.alive = self.presence.alive  # (the same array: alive as recorded)
        self.counts: dict[str, int] = {}  # messages rejected per process (from the clock and the reports)
        self.invalid = 0  # messages this process dropped (the runtime's Invalid)
        self.counted_at: float | None = None  # when the counters were last put in the record
        self.p = s.starts.copy()
        self.theta = s.headings.copy()
        self.pending: dict[int, wire.Truth] = {}
        self.written = resume.k if resume else -1
        self.t = resume.t_s if resume else 0.0
        self.committed_t = self.t
        self.mission_start_unix = resume.mission_start_unix if resume else None
        self.end: wire.Clock | None = None  # the end claimed by an admitted clock, until refused (see _ended)
        self.end_at = 0.0
        self.end_source = ""
        self.world_gone_at: float | None = None  # the world's token went (after a claimed end: the world's own)
        self.conflict_t: float | None = None  # first conflicting command a process reported (simulated s)
        self.mode: str | None = None
        self.guessed_k = -1  # the first tick an agent acted on without all its data (lockstep; -1: none)
        self.wall0: float | None = None  # when the first clock came
        self.min_gap = float("inf")
        self.last_clock_s = 0.0
        self.stall_since: float | None = None  # wall time the world's stall began
        self.stall_t = 0.0
        self.judge_at: float | None = None  # after a stall: when to judge the agents that changed meanwhile

    # ------------------------------------------------------------------------------------- the contract

    def step(self, inputs: Iterable[Input], now_s: float) -> list[Output]:
        """Take what arrived, judge who is alive, record what came; the end (or a Stop) closes the record."""
        self.rows.out = []
        stop = False
        for m in inputs:
            if isinstance(m, Stop):
                stop = True
            else:
                self._take(m, now_s)
        self._sync(now_s)
        written = self.written
        done = self._poll(now_s)
        if self.written != written:
            self.rows.out.append(self._scene())
        if done or stop:
            self._ended()  # (stopped with an end pending: the record must not claim it either)
            self._finish(now_s)
            self.rows.out.append(Exit(0, "stopped" if stop and not done else "recorded"))
        elif self.counted_at is None or now_s - self.counted_at > self.timing.commit_wall_s:
            self.counted_at = now_s
            self._count()
        out: list[Output] = list(self.rows.out)
        self.rows.out = []
        return out

    def wake_at_s(self) -> float | None:
        """No deadline finer than the runtime's poll (`monitor_wake_s`), which steps it for its timers."""
        return None

    def awaiting(self, now_s: float) -> int | None:
        """Only the truth (urgent) or the poll moves the monitor on: it is off the critical path."""
        return None

    def _take(self, m: Input, now_s: float) -> None:
        if isinstance(m, wire.Truth):
            self._truth(m)
        elif isinstance(m, ClockFrom):
            self._clock(m.clock, now_s, m.source)
        elif isinstance(m, Report):
            self._report(m, now_s)
        elif isinstance(m, Token):
            if m.role is Role.AGENT and m.agent is not None:
                if m.agent in self.index:
                    self.presence.members.token(m.agent, m.up, now_s, self.t)
                    self._sync(now_s)
            elif m.role is Role.WORLD:
                self._world_up(m.up, now_s)
        elif isinstance(m, RouterReach):
            self.presence.members.link(m.up, now_s, self.t)
        elif isinstance(m, Invalid):
            self.invalid += 1

    def _scene(self) -> Scene:
        rec = self.rec
        rejected = sum(v for p, v in self.counts.items() if p != "monitor") + self.invalid
        return Scene(self.written, self.t, self.p.copy(), self.theta.copy(), self.alive.copy(),
                     rec.topology.edges.copy(), rec.topology.n_groups, rec.max_error_m, rec.gaps_m, self.min_gap,
                     rejected)

    def _put(self, out: Output) -> None:
        self.rows.out.append(out)

    def _count(self) -> None:
        self.counts["monitor"] = self.invalid
        self._put(Counters(tuple(self.counts.items())))

    # ------------------------------------------------------------------------------------- events

    def _emit(self, ev: Event) -> None:
        """Record, then publish: the same object (the recorder puts it among the outputs)."""
        self.rec.event(ev)

    def _wall(self, now_s: float) -> float:
        return round(now_s + self.unix_offset_s, 6)

    def _sync(self, now_s: float) -> None:
        """Who is alive (monitor/presence.py), as it changes; held while the world stalls and until judged."""
        held = self.stall_since is not None or self.judge_at is not None
        for ev in self.presence.sync(now_s, self.t, self.wall0 is not None, self.end is not None, held):
            self._emit(ev)

    # ------------------------------------------------------------------------------------- the world

    def _world_up(self, up: bool, now_s: float) -> None:
        self.world_gone_at = None if up else now_s
        if not up and self.wall0 is not None and self.end is None:
            self._stalled(now_s, "its token is gone")

    def _stalled(self, now_s: float, why: str) -> None:
        if self.stall_since is None:
            self.stall_since, self.stall_t = self.last_clock_s, self.t  # since the world was last heard
            log.warning("the world stalls at t=%.2f (%s): agents' tokens are not judged until it is back", self.t,
                        why)

    def _refuse_end(self, why: str) -> None:
        """The end claimed is not the world's: refused (counted by the process's gate with its source); recording
        goes on."""
        assert self.end is not None
        log.warning("an end at t=%.2f (%s) refused: %s", self.end.t, self.end.reason, why)
        self._put(RefusedEnd(self.end_source, f"end {self.end.reason!r} at tick {self.end.k}: {why}"))
        self.end = None

    def _clock(self, c: wire.Clock, now_s: float, source: str) -> None:
        # The world ticks on: it did not end (it puts nothing after its own end; a forged end may claim any tick).
        if self.end is not None and not c.end:
            self._refuse_end(f"the world's clock goes on (tick {c.k})")
        self.last_clock_s = now_s
        # A clock within burst_s of the world's token going was put before it went (samples and liveliness changes
        # reach us on different threads, in either order): a world killed right after a tick is not back.
        put_before = self.world_gone_at is not None and now_s - self.world_gone_at < self.timing.burst_s
        if self.stall_since is not None and not put_before:
            self._emit(Event(round(self.stall_t, 9), EventKind.WORLD_STALLED,
                            duration_s=round(now_s - self.stall_since, 3), wall_unix=self._wall(now_s)))
            log.warning("the world is back after %.1f s", now_s - self.stall_since)
            self.stall_since, self.judge_at = None, now_s + self.timing.burst_s
        self.t = max(self.t, c.t)
        if self.mode != c.mode:
            self._put(Meta((("mode", str(c.mode)),)))
        self.mode = str(c.mode)
        self.counts["simworld"] = c.rejected
        if self.wall0 is None:
            self.wall0 = now_s
            if self.resume is None:
                start = f"{now_s + self.unix_offset_s:.6f}"
                self.mission_start_unix = float(start)
                self._put(Meta((("mission_start_unix", start),)))
        if c.end and self.end is None:
            self.end, self.end_at, self.end_source = c, now_s, source
            if c.reason not in WORLD_END_REASONS:
                self._refuse_end("no end the world gives")

    # ------------------------------------------------------------------------------------- data

    def _truth(self, tr: wire.Truth) -> None:
        if any(a not in self.index for a in tr.ids):  # (the world's own session: never a stranger's)
            log.warning("a truth names an agent that is not in the scenario: dropped")
            self.invalid += 1
        elif tr.k > self.written:
            self.pending[tr.k] = tr

    def _report(self, r: Report, now_s: float) -> None:
        """Another process's report (admitted: from its own session): an agent's counters and heartbeat; a
        tally of intrusions when it changed, and the conflicting commands in it."""
        aid = r.agent_id
        if aid is not None:
            if aid not in self.index:
                self.invalid += 1
                return
            self.presence.members.data(aid, now_s, self.t)
            self._telemetry(aid, r.rejected, r.guessed_k)
        if r.rows is not None:
            self._put(Intrusions(r.process, r.rows))
            for kind, _src, _n, first_t in r.rows:
                if kind == IntrusionKind.CONFLICT.value:
                    self._conflict(first_t)

    def _conflict(self, first_t: float) -> None:
        """A process refused a conflicting command (two different commands for one agent's tick): the run is no
        longer the in-process engine's, whatever else happened."""
        if self.conflict_t is None:
            log.warning("conflicting commands at t=%.2f: the run is not deterministic", first_t)
        self.conflict_t = first_t if self.conflict_t is None else min(self.conflict_t, first_t)

    def _telemetry(self, agent_id: int, rejected: int, guessed_k: int) -> None:
        """An agent's counters (from its report): messages it rejected, the first tick it guessed (-1: none)."""
        self.counts[f"agent {agent_id}"] = rejected
        if guessed_k >= 0 and (self.guessed_k < 0 or guessed_k < self.guessed_k):
            if self.guessed_k < 0:
                log.warning("agent %d acted on tick %d without all its data: lockstep is no longer deterministic",
                            agent_id, guessed_k)
            self.guessed_k = guessed_k

    def _flush(self) -> None:
        """Record the ticks received, in order; ticks that never came are a gap in the record."""
        dt = self.s.meta.dt_s
        while self.pending:
            k = min(self.pending)
            tr = self.pending.pop(k)
            for aid, px, py, th in zip(tr.ids, tr.px, tr.py, tr.theta, strict=True):
                i = self.index[aid]
                self.p[i] = (px, py)
                self.theta[i] = th
            t = k * dt
            if self.resume is not None and self.written == self.resume.k:
                self._put(Gap(self.resume.t_s, t, "monitor restarted: ticks in between not recorded"))
                self.rec.topology.confirmed = None  # a fresh start: no events across the gap
            elif self.written >= 0 and k > self.written + 1:
                self._put(Gap(self.written * dt, t, f"ticks {self.written + 1}..{k - 1} never received"))
                log.warning("ticks %d..%d never received: noted as a gap in the record", self.written + 1, k - 1)
            self.rec.tick(k, t, self.p, self.theta, self.alive.copy())  # (its events and rows: outputs)
            self.written, self.t = k, t
            self.min_gap = min(self.min_gap, self.rec.safety.min_agent_gap_m)
            if t - self.committed_t >= self.timing.commit_sim_s:  # a killed monitor loses at most this much
                self._put(Commit(t))
                self.committed_t = t

    def _poll(self, now_s: float) -> bool:
        """Record what came, detect bursts and stalls; True once the mission's end is recorded."""
        self._flush()
        if self.end is None:
            if self.wall0 is not None and now_s - self.last_clock_s >= self.timing.world_stall_s:
                self._stalled(now_s, f"no clock for {now_s - self.last_clock_s:.1f} s")
            if self.judge_at is not None and now_s >= self.judge_at and self.stall_since is None:
                self.judge_at = None
                for ev in self.presence.judge(now_s, self.t):
                    self._emit(ev)
            for ev in self.presence.network(now_s):
                self._emit(ev)
            return False
        # A claimed end stands once its tick is recorded and the world is gone (it closes its session after its
        # end: a forger's clock is followed by the world's), or after end_grace_s; the truth must not contradict
        # it: "converged" is refused unless the record's own error says so at its tick (or, its tick never come,
        # at the last one recorded, which the summary will judge).
        gone = self.world_gone_at is not None and self.world_gone_at >= self.end_at
        late = now_s - self.end_at > self.timing.end_grace_s
        if (self.written >= self.end.k or late) and self._ended():
            return False
        return (self.written >= self.end.k and gone) or late

    def _ended(self) -> bool:
        """A claimed "converged" that the record's truth contradicts is refused (True)."""
        if self.end is None or self.end.reason != "converged" or self.rec.converged():
            return False
        self._refuse_end(f"the truth is not converged (max |e| {self.rec.max_error_m:.3g} m at tick {self.written})")
        return True

    def _finish(self, now_s: float) -> None:
        """Close the record: counters, the end reason (or the world's loss), the wall time."""
        self._count()
        extra: dict[str, Any] = {}
        if self.end is not None:  # (its statistics: only the world's counters, checked; the rest is dropped)
            extra, dropped = world_stats(self.end.stats)
            if dropped:
                log.warning("the end's statistics %s are not the world's counters: dropped", sorted(dropped))
                self.invalid += 1
                self._count()
            extra["end_reason"] = self.end.reason
        elif self.stall_since is not None:
            self._emit(Event(round(self.stall_t, 9), EventKind.WORLD_LOST,
                            duration_s=round(now_s - self.stall_since, 3), wall_unix=self._wall(now_s)))
            extra["end_reason"] = "world lost"
            if self.presence.deferred:
                log.info("not judged (the world was lost): agents %s", sorted(self.presence.deferred))
        # Lockstep equals the in-process engine unless an agent had to act without all of a tick's data, or the
        # world stepped a robot without that tick's command (its end statistics say the first such tick).
        # A conflicting command (someone else spoke for an agent) loses it too.
        uncommanded = extra.pop("uncommanded_from_s", None)
        lost = [t for t in (self.guessed_k * self.s.meta.dt_s if self.guessed_k >= 0 else None, self.conflict_t,
                            uncommanded) if t is not None]
        extra["deterministic"] = self.mode == "lockstep" and not lost
        extra["determinism_lost_at_s"] = round(min(lost), 9) if lost else None
        finished = self.end is not None and self.end.reason != "stopped"  # (stopped: the mission was cut short)
        start = self.mission_start_unix  # from the first clock, whichever monitor incarnation saw it
        wall = None if start is None else now_s + self.unix_offset_s - start
        self._put(Close(extra, finished, wall, self.mode or None))
