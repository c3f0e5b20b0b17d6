"""A process's gate: admission of decoded messages, the tally of intrusions, their log and reports.

Pure (no zenoh): a process's port decodes a sample, passes it here with its source (`inbox.sample_source`),
and delivers it to its node only if `admit` says so. Refusals are counted per (kind, source), logged (the
first of each kind and source at once, then at most one line a second), and summed up in a `Report` that
the port publishes on `swarm/<run>/report/<process>` at most once a second when it changed (an
agent's report is also its heartbeat, with its counters: reconswarm/net/wire/report.py).
"""

from __future__ import annotations

import logging

from reconswarm.net.trust.admission import Admission, HullChecks, Intrusion
from reconswarm.net.trust.tally import IntrusionTally
from reconswarm.net.wire import wire
from reconswarm.net.wire.report import Report
from reconswarm.scenario.model import Scenario

log = logging.getLogger("reconswarm.admission")
Message = wire.Beacon | wire.Cmd | wire.ObstacleSet | wire.Clock | wire.State | wire.Scan | wire.Truth | Report


class Gate:
    def __init__(self, s: Scenario, process: str, report_every_s: float = 1.0, hulls: HullChecks | None = None,
                 adm: Admission | None = None) -> None:
        """hulls: the process's hull checks, shared by its agents' gates (a question about the hull alone); adm: the
        process's admission, shared by an agent host's gates (what one of them admits, all do)."""
        self.process = process
        self.adm = adm or Admission(s, hulls=hulls)
        self.tally = IntrusionTally()
        self.t = 0.0  # simulated time of the newest admitted clock (first_t of the intrusions)
        self.world_k = -1  # newest tick of the admitted clocks
        self.report_every_s = report_every_s
        self._reported = 0  # nothing to report before the first intrusion
        self._last_report = -1e9
        self._last_beat, self._guessed = -1e9, -1  # (agents: the last heartbeat, the guessed_k it carried)
        self._last_log = -1e9
        self._unlogged = 0

    @property
    def count(self) -> int:
        return self.tally.total

    def check(self, m: Message, source: str, key: str, now_s: float) -> Intrusion | None:
        """The rules for m, nothing counted: None admits it (an admitted clock is the gate's newest, `clocked`).
        An agent host judges each remote sample once for every hosted agent it is for (agent/host.py), whose gates
        share one Admission (agent/process.py) and each count a refusal."""
        adm = self.adm
        got: Intrusion | None
        if isinstance(m, wire.Beacon):  # (most of what an agent takes: first)
            got = adm.check_beacon(m, source, key, now_s, self.world_k)
        elif isinstance(m, wire.Clock):
            got = adm.check_clock(m, source, key)
            if got is None:
                self.clocked(m)
        elif isinstance(m, wire.Cmd):
            got = adm.check_cmd(m, source, key, now_s, self.world_k)
        elif isinstance(m, wire.ObstacleSet):
            got = adm.check_obstacles(m, source, key)
        elif isinstance(m, Report):
            got = adm.check_report(m.agent_id, source, key, now_s)
        else:  # state, scan, truth: the world's
            got = adm.check_world_source(source, key)
        return got

    def clocked(self, c: wire.Clock) -> None:
        """An admitted clock: its tick and time are the newest (the intrusions' first_t)."""
        self.t, self.world_k = max(self.t, c.t), max(self.world_k, c.k)

    def admit(self, m: Message, source: str, key: str, now_s: float) -> bool:
        """True: deliver m. False: it was refused, counted and logged."""
        got = self.check(m, source, key, now_s)
        if got is None:
            return True
        self.refuse(got, now_s)
        return False

    def admit_odometry(self, st: wire.State, source: str, key: str, now_s: float) -> bool:
        """A robot's odometry (ROS 2 mode), decoded as its state: True to deliver it."""
        got = self.adm.check_odometry(st, source, key, self.world_k)
        if got is None:
            return True
        self.refuse(got, now_s)
        return False

    def admit_twist(self, c: wire.Cmd, source: str, key: str, now_s: float) -> bool:
        """A ROS 2 cmd_vel (no tick of its own: c.k is the one the plant dates it to, no later than the newest
        published): True to apply it."""
        got = self.adm.check_cmd(c, source, key, now_s, self.world_k, ticked=False)
        if got is None:
            return True
        self.refuse(got, now_s)
        return False

    def admit_set_bytes(self, n_bytes: int, source: str, key: str, now_s: float) -> bool:
        """An obstacle set's payload, before it is decoded: False if larger than any the run can send."""
        got = self.adm.check_set_size(n_bytes, source, key)
        if got is None:
            return True
        self.refuse(got, now_s)
        return False

    def refuse(self, i: Intrusion, now_s: float) -> None:
        first = self.tally.add(i, self.t)
        if first or now_s - self._last_log >= 1.0:
            more = f" (+{self._unlogged} more since the last line)" if self._unlogged else ""
            log.warning("%s: intrusion refused: %s from %s on %s: %s%s [total %d]", self.process, i.kind.value,
                        i.source, i.key, i.detail, more, self.tally.total)
            self._last_log = now_s
            self._unlogged = 0
        else:
            self._unlogged += 1

    def report(self, now_s: float, final: bool = False, counters: tuple[int, int] | None = None,
               every_s: float | None = None) -> Report | None:
        """What to publish on the process's report key, if anything: the tally when it changed (at most every
        report_every_s, or now if `final`); with `counters` (an agent's rejected count and guessed_k) also
        every `every_s` (its heartbeat), at once when guessed_k changed, and always if `final`."""
        total = self.tally.total
        rows_due = total != self._reported and (final or now_s - self._last_report >= self.report_every_s)
        beat_due = counters is not None and (final or counters[1] != self._guessed
                                             or (every_s is not None and now_s - self._last_beat >= every_s))
        if not (rows_due or beat_due):
            return None
        if rows_due:
            self._reported, self._last_report = total, now_s
        if counters is not None:
            self._last_beat, self._guessed = now_s, counters[1]
        rejected, guessed_k = counters or (0, -1)
        return Report(self.process, tuple(self.tally.as_rows()) if rows_due else None, rejected, guessed_k)
