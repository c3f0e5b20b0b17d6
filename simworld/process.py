"""`reconswarm simworld`: the world process. Owns the plant, emulates sensing, keeps the clock.

Per tick k it publishes the clock (with the live agents), every robot's state and, where there is
something to see, its scan; then integrates the commanded u. A robot whose command is missing is held
(last command) for `hold_s`, then stopped; a robot whose agent is gone stays where it stopped.

The mission starts when every agent and the monitor have declared their liveliness tokens (the
readiness barrier); if they have not within `start_timeout_s`, exit 3 naming who is missing.
Clocks: `lockstep` advances when the command for tick k of every live agent is in (deterministic, the
same trajectories as `reconswarm sim`); `realtime` advances every dt/speed seconds of wall time on the
latest commands and measures state-to-command latency and missed deadlines.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zenoh

from reconswarm.errors import BadInput, ProcessFailure
from reconswarm.net import wire
from reconswarm.net.session import Inbox, Member, Rejections, Stopper, ZenohOptions, serving
from reconswarm.paper.planner import errors
from reconswarm.scenario import Scenario, load
from reconswarm.sim import unicycle
from reconswarm.sim.sensing import ContourField

log = logging.getLogger("reconswarm.simworld")
CLOCKS = ("lockstep", "realtime")
REPUBLISH_S = 0.5  # lockstep: re-publish a tick that has waited this long for commands


@dataclass(frozen=True)
class WorldConfig:
    scenario: Path
    zenoh: ZenohOptions
    clock: str = "lockstep"
    speed: float = 10.0
    run_id: str | None = None
    start_timeout_s: float = 60.0
    step_timeout_s: float = 5.0  # lockstep: longest wait for a live agent's command
    hold_s: float = 0.2  # a missing command is held this long, then the robot stops
    no_agents_grace_s: float = 30.0  # with no agent reachable, hold this long before ending the mission


class World(Member):
    def __init__(self, cfg: WorldConfig, s: Scenario, session: zenoh.Session) -> None:
        self.cfg, self.s, self.z = cfg, s, session
        self.keys = wire.Keys(cfg.run_id or s.meta.name)
        self.ids = [a.id for a in s.agents]
        self.index = {a: k for k, a in enumerate(self.ids)}
        self.p = s.starts.copy()
        self.theta = s.headings.copy()
        self.l = s.head_offsets
        self.slots = np.asarray(s.target_m) + s.offsets
        self.field = ContourField.from_scenario(s)
        self.u = np.zeros((len(self.ids), 2))
        self.u_k = np.full(len(self.ids), -(10**9))  # tick of each robot's last command
        self.cmds: dict[int, dict[int, np.ndarray]] = {}  # tick -> agent index -> u
        self.alive: set[int] = set()
        self.ever: set[int] = set()
        self.strikes: dict[int, int] = {}  # lockstep: consecutive step timeouts of each agent
        self.unresponsive: set[int] = set()  # not waited for until they command again
        self.monitor_up = False
        self.inbox = Inbox()
        self.rej = Rejections("simworld")
        self.pub_time: dict[int, float] = {}
        self.latency_ms: list[float] = []
        self.missed = 0
        self.expected = 0
        self.overruns = 0
        block = zenoh.CongestionControl.BLOCK
        z = session
        k = self.keys
        self.pub_clock = z.declare_publisher(k.clock, congestion_control=block)
        self.pub_truth = z.declare_publisher(k.truth, congestion_control=block)
        self.pub_state = {a: z.declare_publisher(k.state(a), congestion_control=block)
                          for a in self.ids}
        self.pub_scan = {a: z.declare_publisher(k.scan(a), congestion_control=block)
                         for a in self.ids}
        self.subs = [z.declare_subscriber(k.all_agents("cmd"), self.inbox.callback),
                     z.liveliness().declare_subscriber(k.alive_all, self.inbox.callback, history=True)]
        self.token = z.liveliness().declare_token(k.alive_simworld)

    def handle(self, key: str, payload: bytes, kind: str) -> None:
        try:
            what, aid, leaf = self.keys.parse(key)
            if what == "alive":
                if leaf == "monitor":
                    self.monitor_up = kind != "DELETE"
                elif leaf == "agent" and aid in self.index:
                    if kind == "DELETE":
                        self.alive.discard(aid)
                        log.warning("agent %d is gone", aid)
                    else:
                        self.alive.add(aid)
                        self.ever.add(aid)
                return
            if what == "agent" and leaf == "cmd" and aid is not None:
                c = wire.cmd_from_wire(payload, aid)
                if aid not in self.index:
                    raise wire.WireError(f"agent {aid} is not in the scenario")
                self.cmds.setdefault(c.k, {})[self.index[aid]] = np.array([c.ux, c.uy])
                if aid in self.unresponsive:
                    self.unresponsive.discard(aid)
                    self.strikes.pop(aid, None)
                    log.info("agent %d commands again", aid)
                sent = self.pub_time.get(c.k)
                if sent is not None and self.cfg.clock == "realtime":
                    self.latency_ms.append((time.monotonic() - sent) * 1000.0)
        except wire.WireError as exc:
            self.rej.reject(key, str(exc))

    def pump(self, timeout: float) -> None:
        item = self.inbox.get(timeout)
        if item is not None:
            self.handle(*item)
            for more in self.inbox.drain():
                self.handle(*more)

    def wait_ready(self, stop: Stopper) -> None:
        deadline = time.monotonic() + self.cfg.start_timeout_s
        while not stop.stopped:
            if self.monitor_up and set(self.ids) <= self.alive:
                return
            if time.monotonic() > deadline:
                missing = [f"agent {a}" for a in self.ids if a not in self.alive]
                if not self.monitor_up:
                    missing.append("monitor")
                raise ProcessFailure(f"simworld: not up after {self.cfg.start_timeout_s:.0f} s: {', '.join(missing)}")
            self.pump(0.05)

    def publish(self, k: int, end: bool, reason: str) -> None:
        t = k * self.s.meta.dt_s
        alive = sorted(self.alive)
        stats = self.stats() if end else {}
        self.pub_clock.put(wire.clock_to_wire(wire.Clock(k, t, tuple(alive), self.cfg.clock,
                                                         self.cfg.speed if self.cfg.clock == "realtime" else 0.0,
                                                         end, reason, self.rej.count, stats)))
        true_d = self.field.true_distances(self.p, self.s.planner.sensing_range_m)
        qa, qs = self.field.scan(self.p, self.s.planner.sensing_range_m, true_d)
        counts = np.bincount(qa, minlength=len(self.ids))
        s_centre = unicycle.body_centre(self.p, self.theta, self.l)
        self.pub_time[k] = time.monotonic()
        self.pub_truth.put(wire.truth_to_wire(wire.Truth(
            k, t, tuple(self.ids), tuple(s_centre[:, 0].tolist()), tuple(s_centre[:, 1].tolist()),
            tuple(self.theta.tolist()), tuple(self.p[:, 0].tolist()), tuple(self.p[:, 1].tolist()))))
        for i, a in enumerate(self.ids):
            self.pub_state[a].put(wire.state_to_wire(wire.State(
                a, k, t, float(s_centre[i, 0]), float(s_centre[i, 1]), float(self.theta[i]), float(self.p[i, 0]),
                float(self.p[i, 1]), int(counts[i]))))
        if qa.size:
            starts = np.searchsorted(qa, np.arange(len(self.ids)))
            ends = np.searchsorted(qa, np.arange(len(self.ids)), side="right")
            for i in map(int, np.flatnonzero(counts)):
                idx = qs[starts[i]:ends[i]]
                names = self.field.ids
                pts = tuple(zip(*self.field.samples[idx].T.tolist(),
                                [names[o] for o in self.field.owner[idx].tolist()], strict=True))
                self.pub_scan[self.ids[i]].put(wire.scan_to_wire(wire.Scan(self.ids[i], k, t, pts)))
        for kk in [x for x in self.pub_time if x < k - 1000]:
            del self.pub_time[kk]

    def apply(self, k: int) -> None:
        """Choose every robot's u for the step k -> k+1 and integrate."""
        hold = max(1, round(self.cfg.hold_s / self.s.meta.dt_s))
        got = self.cmds.pop(k, {})
        for kk in sorted(x for x in self.cmds if x < k):  # late commands still count as the latest
            for i, u in self.cmds.pop(kk).items():
                if kk > self.u_k[i]:
                    self.u[i], self.u_k[i] = u, kk
        for i, u in got.items():
            self.u[i], self.u_k[i] = u, k
        if self.cfg.clock == "realtime":
            live = [self.index[a] for a in self.alive]
            self.expected += len(live)
            self.missed += sum(1 for i in live if i not in got)
        stale = (k - self.u_k) > hold
        u = np.where(stale[:, None], 0.0, self.u)
        w = self.s.world
        self.p, self.theta = unicycle.step(self.p, self.theta, u, self.l, self.s.meta.dt_s, w.max_speed_mps,
                                           w.max_turn_rate_radps)

    def stats(self) -> dict[str, float]:
        out: dict[str, float] = {"world_overruns": float(self.overruns)}
        if self.latency_ms:
            lat = np.array(self.latency_ms)
            out.update(latency_p50_ms=round(float(np.percentile(lat, 50)), 3),
                       latency_p99_ms=round(float(np.percentile(lat, 99)), 3), latency_samples=float(lat.size))
        if self.cfg.clock == "realtime":
            out.update(missed_deadlines=float(self.missed), deadlines=float(self.expected),
                       missed_deadline_ratio=round(self.missed / self.expected, 5) if self.expected else 0.0)
        return out

    def converged(self) -> bool:
        live = [self.index[a] for a in self.alive]
        if not live:
            return False
        e = errors(self.p[live], np.asarray(self.s.target_m), self.s.offsets[live])
        return bool(e.max() <= self.s.planner.converge_tol_m)

    def run(self, stop: Stopper) -> str:
        n_ticks = round(self.s.meta.duration_s / self.s.meta.dt_s)
        period = self.s.meta.dt_s / self.cfg.speed if self.cfg.clock == "realtime" else 0.0
        t0 = time.monotonic()
        for k in range(n_ticks + 1):
            self.pump(0.0)
            reason = ""
            if self.converged():
                reason = "converged"
            elif k == n_ticks:
                reason = "duration"
            elif stop.stopped:
                reason = "stopped"
            elif not self.alive and not self.wait_for_agents(stop):
                reason = "no agents"
            self.publish(k, bool(reason), reason)
            if reason:
                return reason
            if self.cfg.clock == "lockstep":
                self.wait_commands(k, stop)
            else:
                due = t0 + (k + 1) * period
                if time.monotonic() > due:
                    self.overruns += 1
                while not stop.stopped and time.monotonic() < due:
                    self.pump(max(0.0, due - time.monotonic()))
            self.apply(k)
        return "duration"

    def wait_for_agents(self, stop: Stopper) -> bool:
        """No agent reachable (all gone, or the router restarting): hold the world rather than run on."""
        log.warning("no agent is reachable: holding the world for up to %.0f s", self.cfg.no_agents_grace_s)
        deadline = time.monotonic() + self.cfg.no_agents_grace_s
        while not stop.stopped and not self.alive and time.monotonic() < deadline:
            self.pump(0.1)
        if self.alive:
            log.info("agents reachable again: %s", sorted(self.alive))
        return bool(self.alive)

    def wait_commands(self, k: int, stop: Stopper) -> None:
        """Lockstep: wait for tick k's command of every agent the clock announced (one that joins now starts
        at the next tick). Re-publish the tick while waiting, so data lost in an outage is sent again. An
        agent that has let the step time out twice in a row is not waited for again until it speaks."""
        expected = set(self.alive) - self.unresponsive
        now = time.monotonic()
        deadline, again = now + self.cfg.step_timeout_s, now + REPUBLISH_S
        while not stop.stopped and time.monotonic() < deadline:
            got = self.cmds.get(k, {})
            if all(self.index[a] in got for a in expected & self.alive):
                self.strikes.clear()
                return
            if time.monotonic() > again:
                missing = sorted(a for a in expected & self.alive if self.index[a] not in got)
                log.info("tick %d: still waiting for agents %s: publishing the tick again", k, missing)
                self.publish(k, False, "")
                again = time.monotonic() + REPUBLISH_S
            self.pump(min(0.05, max(0.0, deadline - time.monotonic())))
        missing = sorted(a for a in expected & self.alive if self.index[a] not in self.cmds.get(k, {}))
        log.warning("tick %d: no command from %s within %.1f s: holding their robots", k, missing,
                    self.cfg.step_timeout_s)
        for a in missing:
            self.strikes[a] = self.strikes.get(a, 0) + 1
            if self.strikes[a] >= 2:
                self.unresponsive.add(a)
                log.warning("agent %d is unresponsive: not waiting for it until it commands again", a)

def run(cfg: WorldConfig) -> int:
    if cfg.clock not in CLOCKS:
        raise BadInput(f"--clock: expected lockstep or realtime, got {cfg.clock!r}")
    if not cfg.speed > 0:
        raise BadInput(f"--speed: must be > 0, got {cfg.speed}")
    s = load(cfg.scenario)
    with serving(cfg.zenoh, "simworld") as (session, stop):
        world = World(cfg, s, session)
        log.info("simworld up (run %s, %s clock): waiting for %d agents and the monitor", world.keys.run,
                 cfg.clock, len(world.ids))
        world.wait_ready(stop)
        if stop.stopped:
            return 0
        log.info("all up: mission starts")
        wall0 = time.monotonic()
        reason = world.run(stop)
        log.info("mission ended (%s) after %.2f s wall; stats %s", reason, time.monotonic() - wall0, world.stats())
        time.sleep(0.3)  # let the last messages reach the monitor before the session closes
        world.close()
        return 0
