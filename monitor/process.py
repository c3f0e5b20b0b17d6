"""`reconswarm monitor record`: the monitor process.

Records the truth (every robot's state, from simworld) and what agents announce (beacons), computes
safety metrics and topology events live with the same Recorder as the in-process engine, publishes the
events on `swarm/<run>/event`, and writes run.db as it goes (same schema, so every monitor command
works on it). Membership comes from liveliness tokens: a token that disappears is `agent_lost`, one
that comes back `agent_joined`. Restarted on an existing run.db it appends, and notes the gap.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from reconswarm.net import wire
from reconswarm.net.session import Inbox, Member, Rejections, Stopper, ZenohOptions, serving
from reconswarm.record.recorder import Recorder
from reconswarm.record.store import RunWriter
from reconswarm.scenario import Scenario, load

log = logging.getLogger("reconswarm.monitor")
END_GRACE_S = 3.0  # after the world's last clock, how long to wait for the last states
CHANNEL_DEPTH = 1 << 20  # samples a queue holds (deep enough that zenoh never waits for the monitor)
POLL_S = 0.002  # with nothing queued, look again after this long
BURST_S = 1.0  # agents lost (or back) within this much wall time of each other count as one network event
COMMIT_SIM_S = 0.5  # commit the record at least every this much simulated time (and every 0.5 s of wall time)


@dataclass(frozen=True)
class MonitorConfig:
    scenario: Path
    db: Path
    zenoh: ZenohOptions
    run_id: str | None = None
    live: bool = False


class MonitorNode(Member):
    def __init__(self, cfg: MonitorConfig, s: Scenario, session: Any) -> None:
        import zenoh

        self.cfg, self.s = cfg, s
        self.keys = wire.Keys(cfg.run_id or s.meta.name)
        self.ids = [a.id for a in s.agents]
        self.index = {a: k for k, a in enumerate(self.ids)}
        n = len(self.ids)
        append = cfg.db.exists()
        self.writer = RunWriter(cfg.db, s, "lockstep", append=append)
        self.resume_from = self.writer.last_tick() if append else None
        self.rec = Recorder(s, self.writer)
        self.rej = Rejections("monitor")
        self.counts: dict[str, int] = {}
        self.inbox = Inbox()
        self.p = s.starts.copy()
        self.theta = s.headings.copy()
        self.pending: dict[int, wire.Truth] = {}
        self.beacons: dict[int, dict[int, wire.Beacon]] = {}
        self.written = self.resume_from[0] if self.resume_from else -1
        self.t = self.resume_from[1] if self.resume_from else 0.0
        self.alive = np.zeros(n, dtype=bool)
        self.seen = np.zeros(n, dtype=bool)
        self.end: wire.Clock | None = None
        self.end_at = 0.0
        self.mode: str | None = None
        self.wall0: float | None = None
        self.min_gap = float("inf")
        self.committed_t = self.t
        self.burst_lost: list[int] = []  # agents lost in the current burst (network split detection)
        self.burst_lost_at = self.burst_lost_t = 0.0
        self.burst_before: list[int] = []
        self.burst_back: list[int] = []
        self.burst_back_at = self.burst_back_t = 0.0
        self.partitioned: set[int] = set()
        z = session
        k = self.keys
        self.pub_event = z.declare_publisher(k.event, congestion_control=zenoh.CongestionControl.BLOCK)
        cb = self.inbox.callback
        # Data arrives in queues read by the loop in batches (the monitor is off the lockstep's critical
        # path, so it need not wake for every message); liveliness changes come through the inbox.
        self.channels = [z.declare_subscriber(key, zenoh.handlers.FifoChannel(CHANNEL_DEPTH))
                         for key in (k.truth, k.all_agents("beacon"), k.clock)]
        self.subs = [z.liveliness().declare_subscriber(k.alive_all, cb, history=True)]
        self.token = z.liveliness().declare_token(k.alive_monitor)

    def emit(self, ev: dict[str, Any]) -> None:
        ev = {**ev, "wall_unix": round(time.time(), 6)}  # when the monitor noticed, for fault-detection latency
        self.writer.event(ev)
        self.pub_event.put(wire.event_to_wire(wire.Event(
            float(ev["t"]), ev["kind"], tuple(tuple(g) for g in ev.get("before", [])),
            tuple(tuple(g) for g in ev.get("after", [])), ev.get("agent"))))

    def membership(self, aid: int, up: bool) -> None:
        i = self.index[aid]
        before = [int(a) for a in np.array(self.ids)[self.alive]]
        if not up and self.alive[i]:
            if not self.burst_lost:
                self.burst_lost_at, self.burst_lost_t, self.burst_before = time.monotonic(), self.t, before
            self.burst_lost.append(aid)
        elif up and not self.alive[i] and aid in self.partitioned:
            if not self.burst_back:
                self.burst_back_at, self.burst_back_t = time.monotonic(), self.t
            self.burst_back.append(aid)
        was = bool(self.alive[i])
        self.alive[i] = up
        after = [int(a) for a in np.array(self.ids)[self.alive]]
        if up and not was and self.seen[i]:
            self.emit({"t": round(self.t, 9), "kind": "agent_joined", "agent": aid, "before": [before],
                       "after": [after]})
            log.info("agent %d joined at t=%.2f", aid, self.t)
        elif not up and was:
            self.emit({"t": round(self.t, 9), "kind": "agent_lost", "agent": aid, "before": [before], "after": [after]})
            log.warning("agent %d lost at t=%.2f", aid, self.t)
        self.seen[i] |= up

    def network_events(self) -> None:
        """Several agents lost together while others stay is the swarm's network splitting: record a split
        (cause "network"); their return, a merge. Single losses stay agent_lost / agent_joined only."""
        now = time.monotonic()
        alive = [int(a) for a in np.array(self.ids)[self.alive]]
        if self.burst_lost and now - self.burst_lost_at >= BURST_S:
            lost = sorted(a for a in set(self.burst_lost) if not self.alive[self.index[a]])
            if len(lost) >= 2 and alive:
                self.emit({"t": round(self.burst_lost_t, 9), "kind": "split", "cause": "network",
                           "before": [self.burst_before], "after": sorted([alive, lost], key=lambda g: g[0])})
                self.partitioned |= set(lost)
            self.burst_lost = []
        if self.burst_back and now - self.burst_back_at >= BURST_S:
            back = sorted(a for a in set(self.burst_back) if self.alive[self.index[a]])
            rest = [a for a in alive if a not in back]
            if back and rest:
                self.emit({"t": round(self.burst_back_t, 9), "kind": "merge", "cause": "network",
                           "before": sorted([rest, back], key=lambda g: g[0]), "after": [alive]})
            self.partitioned -= set(back)
            self.burst_back = []

    def handle(self, key: str, payload: bytes, kind: str) -> None:
        try:
            what, aid, leaf = self.keys.parse(key)
            if what == "alive":
                # Agents leave when the mission ends: that is not a loss.
                if leaf == "agent" and aid in self.index and self.end is None:
                    self.membership(aid, kind != "DELETE")
                return
            if what == "clock":
                c = wire.clock_from_wire(payload)
                self.t = max(self.t, c.t)
                if self.mode != c.mode:
                    self.writer.set_meta(mode=c.mode)
                self.mode = c.mode
                self.counts["simworld"] = c.rejected
                if self.wall0 is None:
                    self.wall0 = time.monotonic()
                    if self.resume_from is None:
                        self.writer.set_meta(mission_start_unix=f"{time.time():.6f}")
                if c.end:
                    self.end, self.end_at = c, time.monotonic()
                return
            if what == "truth":
                tr = wire.truth_from_wire(payload)
                if any(a not in self.index for a in tr.ids):
                    raise wire.WireError("truth names an agent that is not in the scenario")
                if tr.k > self.written:
                    self.pending[tr.k] = tr
                return
            if what != "agent" or aid is None:
                return
            if aid not in self.index:
                raise wire.WireError(f"agent {aid} is not in the scenario")
            if leaf == "beacon":
                b = wire.beacon_from_wire(payload, aid)
                self.counts[f"agent {aid}"] = b.rejected
                if b.k > self.written:
                    self.beacons.setdefault(b.k, {})[aid] = b
        except wire.WireError as exc:
            self.rej.reject(key, str(exc))

    def flush(self, force: bool = False) -> None:
        """Write the ticks received, in order."""
        while self.pending:
            k = min(self.pending)
            tr = self.pending.pop(k)
            for aid, px, py, th in zip(tr.ids, tr.px, tr.py, tr.theta, strict=True):
                i = self.index[aid]
                self.p[i] = (px, py)
                self.theta[i] = th
            t = k * self.s.meta.dt_s
            if self.resume_from is not None and self.written == self.resume_from[0]:
                self.writer.note_gap(self.resume_from[1], t, "monitor restarted: ticks in between not recorded")
                self.rec.topology.confirmed = None  # a fresh start: no events across the gap
            self.rec.tick(k, t, self.p, self.theta, self.alive.copy())
            b = self.beacons.pop(k, {})
            if b:
                bp = np.full((len(self.ids), 2), np.nan)
                for aid, x in b.items():
                    bp[self.index[aid]] = (x.px, x.py)
                self.writer.beacon(k, t, bp)
            for kk in [x for x in self.beacons if x < k]:
                del self.beacons[kk]
            self.written, self.t = k, t
            self.min_gap = min(self.min_gap, self.rec.safety.min_agent_gap_m)
            if t - self.committed_t >= COMMIT_SIM_S:  # a killed monitor loses at most this much of the record
                self.writer.commit()
                self.committed_t = t

    def finish(self) -> None:
        self.counts["monitor"] = self.rej.count
        self.writer.counters(self.counts)
        extra: dict[str, Any] = {}
        if self.end is not None:
            extra = dict(self.end.stats)
            extra["end_reason"] = self.end.reason
        meta: dict[str, Any] = {"extra": extra, "finished": "1" if self.end is not None else "0"}
        start = self.writer.get_meta("mission_start_unix")
        if start is not None:  # from the first clock, whichever monitor incarnation saw it
            meta["wall_time_s"] = f"{time.time() - float(start):.6f}"
        if self.mode:
            meta["mode"] = self.mode
        self.writer.close(**meta)

    def live_view(self) -> Any:
        from rich.table import Table

        table = Table(title=f"reconswarm monitor — run {self.keys.run}")
        for col in ("t (s)", "groups", "smallest gap (m)", "agents alive", "max |e| (m)", "rejected"):
            table.add_column(col)
        table.add_row(f"{self.t:.2f}", str(self.rec.topology.n_groups), f"{self.min_gap:.2f}",
                      f"{int(self.alive.sum())}/{len(self.ids)}", f"{self.rec.max_error_m:.2f}",
                      str(sum(self.counts.values()) + self.rej.count))
        return table

    def run(self, stop: Stopper) -> int:
        live = None
        if self.cfg.live:
            from rich.live import Live

            live = Live(self.live_view(), refresh_per_second=4, transient=False)
            live.start()
        last_counts = time.monotonic()
        try:
            while not stop.stopped:
                for item in self.inbox.drain():
                    self.handle(*item)
                got = 0
                for ch in self.channels:
                    while (sample := ch.try_recv()) is not None:
                        self.handle(str(sample.key_expr), sample.payload.to_bytes(), "PUT")
                        got += 1
                if not got:
                    time.sleep(POLL_S)
                self.flush()
                if self.end is None:
                    self.network_events()
                if self.end is not None:
                    done = self.written >= self.end.k
                    if done or time.monotonic() - self.end_at > END_GRACE_S:
                        self.flush(force=True)
                        break
                if time.monotonic() - last_counts > 0.5:
                    self.counts["monitor"] = self.rej.count
                    self.writer.counters(self.counts)
                    self.writer.maybe_commit()
                    last_counts = time.monotonic()
                    if live is not None:
                        live.update(self.live_view())
        finally:
            if live is not None:
                live.update(self.live_view())
                live.stop()
            self.finish()
        return 0

def run(cfg: MonitorConfig) -> int:
    s = load(cfg.scenario)
    with serving(cfg.zenoh, "monitor") as (session, stop):
        node = MonitorNode(cfg, s, session)
        log.info("monitor up (run %s): recording to %s", node.keys.run, cfg.db)
        code = node.run(stop)
        node.close()
        log.info("monitor done: %d ticks recorded, %d messages rejected", node.written + 1, node.rej.count)
        return code
