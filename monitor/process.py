"""`reconswarm monitor record`: the monitor process, a thin zenoh adapter around `monitor.node.MonitorNode`.

It decodes the truth, clock, reports and liveliness changes into the node (it does not hear the agents'
beacons: their counters and heartbeat come in their reports, about twice a second, whatever N is), publishes on
`swarm/<run>/event` every event the node has recorded (the same objects, in order), and writes
run.db through the node as it goes (same schema as the in-process engine, so every monitor command
works on it). Restarted on an existing run.db it appends, and notes the gap. A full disk ends it
with exit 3 and a line that says so; what was committed stays readable.
"""

from __future__ import annotations

import errno
import logging
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh
from zenoh import ext

from monitor.live import LiveFeed, LiveView
from monitor.node import MonitorNode
from reconswarm.errors import ProcessFailure
from reconswarm.net import wire
from reconswarm.net.admission import Intrusion, IntrusionKind
from reconswarm.net.gate import Gate
from reconswarm.net.inbox import Inbox, Rejections
from reconswarm.net.keys import Keys, WireError
from reconswarm.net.lifecycle import StartMark, Stopper
from reconswarm.net.membership import Membership
from reconswarm.net.report import report_from_wire
from reconswarm.net.session import Member, ZenohOptions, serving
from reconswarm.net.timing import TIMING
from reconswarm.net.uplink import LinkChange, Uplink
from reconswarm.record.store import RunWriter
from reconswarm.scenario.model import load

log = logging.getLogger("reconswarm.monitor")


@dataclass(frozen=True)
class MonitorConfig:
    scenario: Path
    db: Path
    zenoh: ZenohOptions
    run_id: str | None = None
    live: bool = False
    foxglove_port: int | None = None  # serve the run live to the Foxglove app (monitor/live.py)


def disk_full(exc: BaseException) -> bool:
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return True
    return isinstance(exc, sqlite3.Error) and "full" in str(exc).lower()


class MonitorAdapter(Member):
    def __init__(self, node: MonitorNode, run: str, session: Any) -> None:
        self.node = node
        self.keys = k = Keys(run)
        self.rej = Rejections("monitor")
        self.inbox = Inbox()
        self.feed: LiveFeed | None = None
        self.live_k = -1
        z = session
        self.pub_event = z.declare_publisher(k.event, congestion_control=zenoh.CongestionControl.BLOCK)
        # Everything arrives in the inbox, taken in one batch per tick: the world's truth wakes the loop, the
        # rest (clock, reports, membership) waits for it (the monitor is off the critical path).
        # The truth comes numbered from the world's advanced publisher: one that was lost (published while
        # the world's session came back from a stall) is fetched from its cache, and delivered in order.
        recovery = ext.RecoveryConfig(periodic_queries=None, heartbeat=True)
        self.subs = [ext.declare_advanced_subscriber(z, k.truth, self.inbox.handler(urgent=True), recovery=recovery),
                     *(z.declare_subscriber(key, self.inbox.handler())
                       for key in (k.clock, k.report_all))]
        # Admission (what the run cannot contain is refused and counted, with the other processes' reports);
        # an agent is alive while its token is there AND its own reports (its heartbeat) keep coming; our own
        # session losing its router is no agent's loss (Uplink, Membership.link).
        self.gate = Gate(node.s, "monitor")
        self.members = Membership(confirm_s=node.timing.token_confirm_s)
        self.uplink = Uplink(session, "monitor")
        self.told: dict[int, bool] = {}
        self.subs.append(z.liveliness().declare_subscriber(k.alive_all, self.inbox.handler(), history=True))
        self.token = z.liveliness().declare_token(k.alive_monitor)

    def handle(self, key: str, payload: bytes, kind: str, source: str, at_s: float) -> None:
        node, gate, now = self.node, self.gate, at_s
        try:
            what, aid, leaf = self.keys.parse(key)
            if what == "alive":
                if leaf == "agent" and aid is not None:
                    self.members.token(aid, kind != "DELETE", now, node.t)
                    self.sync(now)
                elif leaf == "simworld":
                    node.world_up(kind != "DELETE", now)
            elif what == "clock":
                c = wire.clock_from_wire(payload)
                if gate.admit(c, source, key, now):
                    node.clock(c, now, source)
            elif what == "truth":
                tr = wire.truth_from_wire(payload)
                if gate.admit(tr, source, key, now):
                    node.truth(tr)
            elif what == "report":
                self.report(key, leaf, aid, payload, source, now)
        except WireError as exc:
            self.rej.reject(key, str(exc))

    def report(self, key: str, process: str, aid: int | None, payload: bytes, source: str, now: float) -> None:
        """Another process's report, if it comes from that process's own session (an agent's session is
        pinned by its first report, as admission pins senders): its tally of intrusions when it changed, and
        an agent's counters and heartbeat."""
        r = report_from_wire(payload, process)
        if not self.gate.admit(r, source, key, now):  # (a whole tally each time: the next one will do)
            return
        if aid is not None:
            self.members.data(aid, now, self.node.t)
            self.node.telemetry(aid, r.rejected, r.guessed_k)
        if r.rows is not None:
            self.node.writer.intrusions(r.process, list(r.rows))
            for kind, _src, _n, first_t in r.rows:
                if kind == IntrusionKind.CONFLICT.value:
                    self.node.conflict(first_t)

    def sync(self, now: float) -> None:
        """Tell the node who is alive by the membership rule (token AND own beacons), as it changes."""
        node = self.node
        if node.wall0 is not None:
            self.members.start(now, node.t)
        for aid in node.ids:
            up = self.members.alive(aid, now, node.t)
            if self.told.get(aid, False) != up:
                self.told[aid] = up
                node.agent_up(aid, up, now)

    def publish(self) -> None:
        for ev in self.node.take_events():
            self.pub_event.put(wire.event_to_wire(ev))
            if self.feed is not None:
                self.feed.view.event(ev)

    def serve(self, view: LiveView, session: Any) -> None:
        """Also serve the run live (--foxglove): the ticks recorded, the events, the agents' obstacle sets."""
        self.feed = LiveFeed(view, self.keys, session, self.rej)

    def feed_live(self, now: float) -> None:
        if self.feed is None:
            return
        self.feed.poll()
        n, view = self.node, self.feed.view
        if n.written >= 0 and n.written != self.live_k and view.due(now):
            self.live_k = n.written
            view.tick(now, n.t, n.p, n.theta, n.alive, n.rec.topology.edges, n.rec.max_error_m, *n.rec.gaps_m)

    def live_view(self) -> Any:
        from rich.table import Table

        n = self.node
        table = Table(title=f"reconswarm monitor — run {self.keys.run}")
        for col in ("t (s)", "groups", "smallest gap (m)", "agents alive", "max |e| (m)", "rejected"):
            table.add_column(col)
        table.add_row(f"{n.t:.2f}", str(n.rec.topology.n_groups), f"{n.min_gap:.2f}",
                      f"{int(n.alive.sum())}/{len(n.ids)}", f"{n.rec.max_error_m:.2f}",
                      str(sum(n.counts.values()) + self.rej.count))
        return table

    def run(self, stop: Stopper, live_on: bool) -> int:
        node = self.node
        live = None
        if live_on:
            from rich.live import Live

            live = Live(self.live_view(), refresh_per_second=4, transient=False)
            live.start()
        last_counts = time.monotonic()
        try:
            mark = StartMark()
            while not stop.stopped:
                mark(node.wall0 is not None)
                items = self.inbox.take(None, TIMING.monitor_wake_s)
                if (change := self.uplink.poll()) is not None:
                    self.members.link(change is LinkChange.UP, time.monotonic(), node.t, node.timing.relink_settle_s)
                for item in items:
                    self.handle(*item)
                self.sync(time.monotonic())
                done = node.poll(time.monotonic())
                for source, why in node.refused_ends:  # ends the world did not decide: intrusions
                    self.gate.refuse(Intrusion(IntrusionKind.END, source, self.keys.clock, why), time.monotonic())
                node.refused_ends.clear()
                self.publish()
                self.feed_live(time.monotonic())
                if done:
                    break
                if time.monotonic() - last_counts > TIMING.commit_wall_s:
                    node.counts["monitor"] = self.rej.count
                    node.writer.counters(node.counts)
                    node.writer.intrusions("monitor", self.gate.tally.as_rows())
                    node.writer.maybe_commit()
                    last_counts = time.monotonic()
                    if live is not None:
                        live.update(self.live_view())
            node.end_contradicted()  # (stopped with an end pending: the record must not claim it either)
            for source, why in node.refused_ends:
                self.gate.refuse(Intrusion(IntrusionKind.END, source, self.keys.clock, why), time.monotonic())
            node.writer.intrusions("monitor", self.gate.tally.as_rows())
            node.finish(time.monotonic(), self.rej.count)
            self.publish()
        except (sqlite3.Error, OSError) as exc:
            if not disk_full(exc):
                raise
            node.writer.abort()
            raise ProcessFailure(f"monitor: disk full: cannot write {node.writer.path} ({exc}); the record keeps "
                                 f"what was committed, up to t = {node.committed_t:.2f} s") from None
        finally:
            if live is not None:
                live.update(self.live_view())
                live.stop()
        return 0


def run(cfg: MonitorConfig) -> int:
    s = load(cfg.scenario)
    append = cfg.db.exists()
    try:
        writer = RunWriter(cfg.db, s, "lockstep", append=append)
        resume_from = writer.last_tick() if append else None
    except (sqlite3.Error, OSError) as exc:
        if disk_full(exc):
            raise ProcessFailure(f"monitor: disk full: cannot write {cfg.db} ({exc})") from None
        raise
    node = MonitorNode(s, writer, resume_from, unix_offset_s=time.time() - time.monotonic())
    with serving(cfg.zenoh, "monitor") as (session, stop):
        adapter = MonitorAdapter(node, cfg.run_id or s.meta.name, session)
        if cfg.foxglove_port is not None:
            view = LiveView(s, cfg.foxglove_port)
            adapter.serve(view, session)
            log.info("live view: ws://127.0.0.1:%d (Foxglove app: Open connection)", view.port)
        log.info("monitor up (run %s): recording to %s", adapter.keys.run, cfg.db)
        try:
            code = adapter.run(stop, cfg.live)
        finally:
            if adapter.feed is not None:
                adapter.feed.close()
        adapter.close()
        log.info("monitor done: %d ticks recorded, %d messages rejected", node.written + 1, adapter.rej.count)
        return code
