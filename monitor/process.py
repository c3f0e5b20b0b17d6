"""`reconswarm monitor record`: the monitor process, `monitor.node.MonitorNode` on the one runtime.

`MonitorAdapter` is the role's declarations (reconswarm/net/runtime/runtime.Adapter): it subscribes to the truth,
the clock, the reports and the liveliness tokens (not to the agents' beacons: their counters and heartbeat come in their
reports, about twice a second, whatever N is), routes each sample through its codec and the gate's admission
to the node (a malformed one is logged and handed over as `Invalid`, counted by the node), publishes on
`swarm/<run>/event` every event the node recorded (the same objects, in order), and hands the node's rows to
run.db (same schema as the in-process engine, so every monitor command works on it). Restarted on an existing
run.db it appends, and notes the gap. A full disk ends it with exit 3 and a line that says so; what was
committed stays readable.
"""

from __future__ import annotations

import errno
import logging
import sqlite3
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh
from zenoh import ext

from monitor.live import LiveFeed, LiveView, status_table
from monitor.messages import ClockFrom, Input, Output, RefusedEnd, Scene
from monitor.node import MonitorNode
from monitor.rows import Close, Commit, Resume, write
from reconswarm.errors import ProcessFailure
from reconswarm.net.node import Exit, Invalid, Token
from reconswarm.net.runtime.inbox import Inbox, Item, Rejections, Tag
from reconswarm.net.runtime.lifecycle import Stopper
from reconswarm.net.runtime.runtime import Runtime
from reconswarm.net.runtime.session import Member, ZenohOptions, serving
from reconswarm.net.timing import TIMING
from reconswarm.net.trust.admission import Intrusion, IntrusionKind
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import BeaconBatch
from reconswarm.net.wire.decode import LIVE_VIEW, MONITOR, decode
from reconswarm.net.wire.hostwire import CmdBatch, StateBatch
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.net.wire.report import Report
from reconswarm.paper.events import Event
from reconswarm.record.store import RunWriter
from reconswarm.scenario.model import Scenario, load

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
    """The monitor's subscriptions, publisher, gate and record around its node (the runtime's Adapter)."""

    def __init__(self, s: Scenario, run: str, session: Any, writer: RunWriter, resume: Resume | None) -> None:
        self.z, self.keys, self.writer = session, Keys(run), writer
        self.committed_t = resume.t_s if resume else 0.0  # the record's last commit point (simulated s)
        self.rej = Rejections("monitor")  # (logs what is dropped; the node counts it)
        self.inbox = Inbox()
        self.accepts = MONITOR  # (and the live view's obstacle sets while it is served: `serve`)
        self.feed: LiveFeed | None = None
        self.live: Any = None  # the rich table (--live)
        self.scene: Scene | None = None  # the newest tick recorded, for the live views (the node's output)
        self.chores_at = time.monotonic()
        k = self.keys
        self.pub_event = session.declare_publisher(k.event, congestion_control=zenoh.CongestionControl.BLOCK)
        # Everything arrives in the inbox, taken in one batch per tick: the world's truth wakes the loop, the
        # rest (clock, reports, membership) waits for it (the monitor is off the critical path).
        # The truth comes numbered from the world's advanced publisher: one that was lost (published while
        # the world's session came back from a stall) is fetched from its cache, and delivered in order.
        recovery = ext.RecoveryConfig(periodic_queries=None, heartbeat=True)
        self.subs = [ext.declare_advanced_subscriber(session, k.truth, self.inbox.handler(urgent=True),
                                                     recovery=recovery),
                     *(session.declare_subscriber(key, self.inbox.handler()) for key in (k.clock, k.report_all)),
                     session.liveliness().declare_subscriber(k.alive_all, self.inbox.handler(), history=True)]
        # Admission: what the run cannot contain is refused and counted, with the other processes' reports.
        self.gate = Gate(s, "monitor")
        self.token = session.liveliness().declare_token(k.alive_monitor)

    # ------------------------------------------------------------------------------------ route

    def route(self, items: Sequence[tuple[Tag, Item]], now_s: float) -> dict[int, list[Input]]:
        return {0: [m for m in (self.decode(*item) for _tag, item in items) if m is not None]}

    def decode(self, key: str, payload: bytes, kind: str, source: str, at_s: float) -> Input | None:
        """A sample as the node's input: admitted by the gate (else None, counted there), or Invalid."""
        try:
            if self.feed is not None and key.endswith("/obstacles") and not self.gate.admit_set_bytes(
                    len(payload), source, key, at_s):  # (the live view's sets: their size, before decoding)
                return None
            m = decode(self.keys, self.accepts, key, payload, kind)
            if m is None or isinstance(m, Token):
                return m
            if isinstance(m, BeaconBatch | StateBatch | CmdBatch):  # (no kind the monitor accepts)
                return None
            # (a report: from the session that speaks for that process; an agent's pinned by its first)
            if not self.gate.admit(m, source, key, at_s):
                return None
            if isinstance(m, wire.ObstacleSet) and self.feed is not None:  # the live view's, not the node's
                self.feed.view.obstacle_set(m)
            elif isinstance(m, wire.Clock):
                return ClockFrom(m, source)
            elif isinstance(m, wire.Truth | Report):
                return m
            return None
        except WireError as exc:
            self.rej.reject(key, str(exc))
            return Invalid(key, str(exc))

    # ------------------------------------------------------------------------------------ act

    def act(self, who: int, out: Output, now_s: float) -> bool:
        if isinstance(out, Event):  # recorded, then published: the same object
            write(self.writer, out)
            self.pub_event.put(wire.event_to_wire(out))
            if self.feed is not None:
                self.feed.view.event(out)
        elif isinstance(out, RefusedEnd):  # an end the world did not decide: an intrusion
            self.gate.refuse(Intrusion(IntrusionKind.END, out.source, self.keys.clock, out.why), now_s)
        elif isinstance(out, Scene):  # (for the live views: `idle`)
            self.scene = out
        elif not isinstance(out, Exit):
            if isinstance(out, Close):
                self.writer.intrusions("monitor", self.gate.tally.as_rows())
            write(self.writer, out)
            if isinstance(out, Commit):
                self.committed_t = out.t_s
        return False

    def idle(self, who: int, now_s: float) -> None:
        """The live view; every `commit_wall_s`: our own tally, a commit, the rich table."""
        if self.feed is not None and self.scene is not None:
            self.feed.follow(self.scene, now_s)
        if now_s - self.chores_at > TIMING.commit_wall_s:
            self.chores_at = now_s
            self.writer.intrusions("monitor", self.gate.tally.as_rows())
            self.writer.maybe_commit()
            if self.live is not None:
                self.live.update(status_table(self.scene, self.keys.run))

    def exited(self, who: int, code: Exit, now_s: float) -> None:
        log.info("monitor: %s", code.reason)

    # ------------------------------------------------------------------------------------ views

    def serve(self, view: LiveView) -> None:
        """Also serve the run live (--foxglove): the ticks recorded, the events, the agents' obstacle sets."""
        self.feed = LiveFeed(view, self.keys, self.z, self.inbox.handler())
        self.accepts = MONITOR | LIVE_VIEW

    # ------------------------------------------------------------------------------------ the loop

    def run(self, node: MonitorNode, stop: Stopper, live_on: bool) -> int:
        """The runtime around the node until it exits; a full disk: the record keeps what was committed."""
        if live_on:
            from rich.live import Live

            self.live = Live(status_table(self.scene, self.keys.run), refresh_per_second=4, transient=False)
            self.live.start()
        try:
            rt = Runtime(self.z, "monitor", stop, self.inbox, node.timing.monitor_wake_s)
            exits = rt.run({0: node}, self, started=lambda: node.wall0 is not None)
        except (sqlite3.Error, OSError) as exc:
            if not disk_full(exc):
                raise
            self.writer.abort()
            raise ProcessFailure(f"monitor: disk full: cannot write {self.writer.path} ({exc}); the record keeps "
                                 f"what was committed, up to t = {self.committed_t:.2f} s") from None
        finally:
            if self.live is not None:
                self.live.update(status_table(self.scene, self.keys.run))
                self.live.stop()
        return exits[0].code if 0 in exits else 0

    def close(self) -> None:
        if self.feed is not None:
            self.feed.close()
        super().close()


def run(cfg: MonitorConfig) -> int:
    s = load(cfg.scenario)
    append = cfg.db.exists()
    try:
        writer = RunWriter(cfg.db, s, "lockstep", append=append)
        resume = Resume.of(writer) if append else None
    except (sqlite3.Error, OSError) as exc:
        if disk_full(exc):
            raise ProcessFailure(f"monitor: disk full: cannot write {cfg.db} ({exc})") from None
        raise
    node = MonitorNode(s, resume, unix_offset_s=time.time() - time.monotonic())
    with serving(cfg.zenoh, "monitor") as (session, stop):
        adapter = MonitorAdapter(s, cfg.run_id or s.meta.name, session, writer, resume)
        try:
            if cfg.foxglove_port is not None:
                view = LiveView(s, cfg.foxglove_port)
                adapter.serve(view)
                log.info("live view: ws://127.0.0.1:%d (Foxglove app: Open connection)", view.port)
            log.info("monitor up (run %s): recording to %s", adapter.keys.run, cfg.db)
            code = adapter.run(node, stop, cfg.live)
        finally:
            adapter.close()
        log.info("monitor done: %d ticks recorded, %d messages rejected", node.written + 1, node.invalid)
        return code
