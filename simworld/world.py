"""The world's tick logic as a pure state machine: no zenoh, no clock of its own.

`WorldNode` owns the plant (unicycles, contour sensing) and decides, from the messages it is handed
and the time `now_s` it is told, what to publish and when to advance:

- readiness barrier: the mission starts when every agent of the scenario and the monitor are up;
  past `start_timeout_s` it fails naming who is missing;
- lockstep: tick k advances when the command for k of every agent the clock announced is in; a tick
  that has waited `republish_s` is published again (data lost in an outage is sent again); after
  `step_timeout_s` the missing robots are held, and an agent that let the step time out `strikes`
  times in a row is not waited for until it commands again;
- realtime: tick k advances at t0 + (k+1) dt / speed on the latest commands (missed deadlines and
  state-to-command latency are counted);
- a robot whose command is missing is held (last command) for `hold_sim_s`, then stopped;
- with no agent reachable the world holds for `no_agents_grace_s`, then ends the mission.

The zenoh adapter (simworld/process.py) feeds `agent_up`, `monitor_up`, `command`, calls `step` and
publishes what it returns.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from enum import Enum, auto

import numpy as np

from reconswarm.errors import ProcessFailure
from reconswarm.net import wire
from reconswarm.net.cells import CellGrid
from reconswarm.net.keys import WireError
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.wire import ClockMode
from reconswarm.paper.planner import errors
from reconswarm.plant import unicycle
from reconswarm.plant.sensing import ContourField
from reconswarm.scenario.model import Scenario

log = logging.getLogger("reconswarm.simworld")


class Phase(Enum):
    READY = auto()  # waiting for everyone (the readiness barrier)
    TICK = auto()  # about to publish tick k
    WAIT_COMMANDS = auto()  # lockstep: tick k published, waiting for its commands
    WAIT_DUE = auto()  # realtime: tick k published, waiting for its deadline
    NO_AGENTS = auto()  # nobody reachable: holding the world
    DONE = auto()


@dataclass
class TickOut:
    """Everything one tick publishes: the clock, the truth, every robot's state (with its scan, if any)."""

    clock: wire.Clock
    truth: wire.Truth
    states: list[wire.State]


@dataclass
class Step:
    """What `WorldNode.step` asks of the adapter: publish `out`, call again by `wake_s` (sooner if a message
    comes), and stop once `ended` holds the mission's end reason."""

    out: list[TickOut] = field(default_factory=list)
    wake_s: float = 0.0
    ended: str | None = None


class WorldNode:
    def __init__(self, s: Scenario, clock: ClockMode = ClockMode.LOCKSTEP, speed: float = 1.0,
                 timing: Timing = TIMING) -> None:
        self.s, self.clock, self.speed, self.timing = s, clock, speed, timing
        self.ids = [a.id for a in s.agents]
        self.index = {a: k for k, a in enumerate(self.ids)}
        self.p = s.starts.copy()
        self.theta = s.headings.copy()
        self.l = s.head_offsets
        self.field = ContourField.from_scenario(s)
        grid = CellGrid.for_scenario(s)
        # Held robots (agents gone) are reported in the scans of agents this near: nearer than anything that
        # can matter to them within the next tick (an agent hears only its cells' beacons).
        self.body_range_m = grid.reach_m + 2.0 * grid.step_m
        n = len(self.ids)
        self.held = np.zeros((n, 2))  # each robot's held input to the plant (`plant_input` of its last command)
        self.held_k = np.full(n, -(10**9))  # tick of each robot's last command
        self.cmds: dict[int, dict[int, np.ndarray]] = {}  # tick -> agent index -> (v, ω)
        self.headings: dict[int, np.ndarray] = {}  # θ at the recent ticks (a late command is its tick's)
        self.alive: set[int] = set()
        self.monitor: bool = False
        self.strikes: dict[int, int] = {}  # lockstep: consecutive step timeouts of each agent
        self.unresponsive: set[int] = set()  # not waited for until they command again
        self.rejected = 0  # messages the adapter dropped (reported on the clock)
        self.pub_time: dict[int, float] = {}
        self.latency_ms: list[float] = []
        self.missed = self.expected = self.overruns = 0
        # Lockstep: the first tick stepped with a robot lacking that tick's command (held or stopped: an agent
        # frozen, lost or timed out), where the run leaves the in-process engine's; -1: none.
        self.uncommanded_k = -1
        self.phase = Phase.READY
        self.k = 0
        self.n_ticks = round(s.meta.duration_s / s.meta.dt_s)
        self.period_s = s.meta.dt_s / speed if clock == ClockMode.REALTIME else 0.0
        self.t0 = 0.0
        self.started = False  # the readiness barrier has passed
        self.deadline_s: float | None = None  # of the phase in progress
        self.again_s = 0.0
        self.waiting_for: set[int] = set()
        self.last_step_s: float | None = None
        self.resumed = False  # the world itself was stalled during this tick's wait
        self.linked, self.unlinked_at = True, 0.0  # our own session has its router (see link)

    # ------------------------------------------------------------------------------------- inputs

    def agent_up(self, aid: int, up: bool) -> None:
        if aid not in self.index:
            return
        if up:
            self.alive.add(aid)
        elif aid in self.alive:
            self.alive.discard(aid)
            log.warning("agent %d is gone", aid)

    def link(self, up: bool, now_s: float) -> None:
        """Our own session lost its router (up=False) or has one again. Meanwhile nobody is reachable: the world
        holds as with no agent (ending the mission after `no_agents_grace_s`), no robot is stepped without its
        command and nobody is lost; realtime's schedule then moves on by the time it held."""
        if up != self.linked:
            self.linked = up
            if up:
                self.t0 += now_s - self.unlinked_at
            else:
                self.unlinked_at = now_s

    def monitor_up(self, up: bool) -> None:
        self.monitor = up

    def command(self, c: wire.Cmd, now_s: float) -> None:
        if c.id not in self.index:
            raise WireError(f"agent {c.id} is not in the scenario")
        self.cmds.setdefault(c.k, {})[self.index[c.id]] = np.array([c.v_mps, c.omega_radps])
        if c.id in self.unresponsive:
            self.unresponsive.discard(c.id)
            self.strikes.pop(c.id, None)
            log.info("agent %d commands again", c.id)
        sent = self.pub_time.get(c.k)
        if sent is not None and self.clock == ClockMode.REALTIME:
            self.latency_ms.append((now_s - sent) * 1000.0)

    def sent(self, k: int, now_s: float) -> None:
        """The adapter put tick k's states on the wire at now_s (for state-to-command latency)."""
        self.pub_time[k] = now_s
        while (oldest := next(iter(self.pub_time))) < k - 1000:  # (oldest first: ticks go out in order)
            del self.pub_time[oldest]

    # ------------------------------------------------------------------------------------- the machine

    def step(self, now_s: float, stopping: bool = False) -> Step:
        """Advance as far as the messages received allow at now_s; at most one tick per call."""
        if self.started and self.stalled(now_s):
            self._own_stall(now_s, now_s - (self.last_step_s or now_s))
        self.last_step_s = now_s
        if not self.linked and not stopping and self.phase in (Phase.WAIT_COMMANDS, Phase.WAIT_DUE):
            self.phase = Phase.TICK  # (tick k is published again once the link is back)
        if self.phase == Phase.READY:
            return self._ready(now_s, stopping)
        if self.phase == Phase.TICK:
            return self._tick(now_s, stopping)
        if self.phase == Phase.NO_AGENTS:
            if self.alive and self.linked:
                log.info("agents reachable again: %s", sorted(self.alive))
                return self._publish_tick(now_s, "")
            if stopping or now_s >= self._deadline(now_s):
                return self._publish_tick(now_s, "no agents")
            return Step([], self._deadline(now_s))
        if self.phase == Phase.WAIT_COMMANDS:
            return self._wait_commands(now_s, stopping)
        if self.phase == Phase.WAIT_DUE:
            if stopping or now_s >= self._deadline(now_s):
                return self._advance(now_s)
            return Step([], self._deadline(now_s))
        return Step([], now_s, "stopped")

    def stalled(self, now_s: float) -> bool:
        """The world itself did not run for `self_stall_s` since its last step (its loop steps every 50 ms at most)."""
        return self.last_step_s is not None and now_s - self.last_step_s >= self.timing.self_stall_s

    def _own_stall(self, now_s: float, gap_s: float) -> None:
        """The world itself did not run for gap_s (SIGSTOP, a starved machine): nobody was late, so no step
        times out for it. Lockstep waits afresh for the agents it waited for (whose tokens may be flapping while
        the sessions reconnect) and publishes the tick again now; realtime shifts its schedule."""
        log.warning("simworld itself was stalled for %.1f s at tick %d: waiting afresh", gap_s, self.k)
        if self.phase == Phase.WAIT_COMMANDS:
            self.deadline_s, self.again_s, self.resumed = now_s + self.timing.step_timeout_s, now_s, True
        elif self.deadline_s is not None:
            self.deadline_s += gap_s
        self.t0 += gap_s

    def _deadline(self, now_s: float) -> float:
        return now_s if self.deadline_s is None else self.deadline_s

    def _ready(self, now_s: float, stopping: bool) -> Step:
        if self.deadline_s is None:
            self.deadline_s = now_s + self.timing.start_timeout_s
        if stopping:
            self.phase = Phase.DONE
            return Step([], now_s, "stopped")
        if self.monitor and set(self.ids) <= self.alive:
            log.info("all up: mission starts")
            self.phase, self.t0, self.deadline_s, self.started = Phase.TICK, now_s, None, True
            return Step([], now_s)
        if now_s > self.deadline_s:
            missing = [f"agent {a}" for a in self.ids if a not in self.alive]
            if not self.monitor:
                missing.append("monitor")
            raise ProcessFailure(f"simworld: not up after {self.timing.start_timeout_s:.0f} s: {', '.join(missing)}")
        return Step([], self.deadline_s)

    def _tick(self, now_s: float, stopping: bool) -> Step:
        reason = ""
        if self.converged():
            reason = "converged"
        elif self.k == self.n_ticks:
            reason = "duration"
        elif stopping:
            reason = "stopped"
        elif not self.alive or not self.linked:
            log.warning("no agent is reachable%s: holding the world for up to %.0f s",
                        "" if self.linked else " (our own link to the router is gone)", self.timing.no_agents_grace_s)
            self.phase, self.deadline_s = Phase.NO_AGENTS, now_s + self.timing.no_agents_grace_s
            return Step([], self.deadline_s)
        return self._publish_tick(now_s, reason)

    def _publish_tick(self, now_s: float, reason: str) -> Step:
        out = [self.tick_out(self.k, reason)]
        if reason:
            self.phase = Phase.DONE
            return Step(out, now_s, reason)
        if self.clock == ClockMode.LOCKSTEP:
            self.waiting_for = set(self.alive) - self.unresponsive
            self.phase, self.deadline_s = Phase.WAIT_COMMANDS, now_s + self.timing.step_timeout_s
            self.again_s = now_s + self.timing.republish_s
            return Step(out, min(self.deadline_s, self.again_s))
        due = self.t0 + (self.k + 1) * self.period_s
        if now_s > due:
            self.overruns += 1
        self.phase, self.deadline_s = Phase.WAIT_DUE, due
        return Step(out, due)

    def awaiting(self) -> int | None:
        """How many messages to wait for before stepping again (the adapter wakes then, or at `wake_s`): the
        commands still missing while a lockstep tick waits for them; None while realtime waits for its due
        time; 1 otherwise (membership changes)."""
        if self.phase == Phase.WAIT_COMMANDS:
            return max(1, len(self.missing()))
        return None if self.phase == Phase.WAIT_DUE else 1

    def missing(self) -> list[int]:
        """Lockstep: agents the current tick still waits for."""
        got = self.cmds.get(self.k, {})
        live = self.waiting_for if self.resumed else self.waiting_for & self.alive
        return sorted(a for a in live if self.index[a] not in got)

    def _wait_commands(self, now_s: float, stopping: bool) -> Step:
        missing = self.missing()
        if not missing:
            self.strikes.clear()
            return self._advance(now_s)
        if stopping or now_s >= self._deadline(now_s):
            log.warning("tick %d: no command from %s within %.1f s: holding their robots", self.k, missing,
                        self.timing.step_timeout_s)
            for a in missing:
                self.strikes[a] = self.strikes.get(a, 0) + 1
                if self.strikes[a] >= self.timing.strikes:
                    self.unresponsive.add(a)
                    log.warning("agent %d is unresponsive: not waiting for it until it commands again", a)
            return self._advance(now_s)
        out = []
        if now_s >= self.again_s:
            log.info("tick %d: still waiting for agents %s: publishing the tick again", self.k, missing)
            out.append(self.tick_out(self.k, ""))
            self.again_s = now_s + self.timing.republish_s
        return Step(out, min(self._deadline(now_s), self.again_s))

    def _advance(self, now_s: float) -> Step:
        self.apply(self.k)
        self.k += 1
        self.phase, self.deadline_s, self.resumed = Phase.TICK, None, False
        return Step([], now_s)

    # ------------------------------------------------------------------------------------- the plant

    def tick_out(self, k: int, reason: str) -> TickOut:
        t = k * self.s.meta.dt_s
        end = bool(reason)
        clock = wire.Clock(k, t, tuple(sorted(self.alive)), self.clock,
                           self.speed if self.clock == ClockMode.REALTIME else 0.0, end, reason, self.rejected,
                           self.stats() if end else {})
        true_d = self.field.true_distances(self.p, self.s.planner.sensing_range_m)
        qa, qs = self.field.scan(self.p, self.s.planner.sensing_range_m, true_d)
        bodies = self.held_bodies()
        counts = np.bincount(qa, minlength=len(self.ids)) + np.array([len(b) for b in bodies], dtype=np.int64)
        c = unicycle.body_centre(self.p, self.theta, self.l)
        truth = wire.Truth(k, t, tuple(self.ids), tuple(c[:, 0].tolist()), tuple(c[:, 1].tolist()),
                           tuple(self.theta.tolist()), tuple(self.p[:, 0].tolist()), tuple(self.p[:, 1].tolist()))
        scans: list[wire.Scan | None] = [None] * len(self.ids)
        starts = np.searchsorted(qa, np.arange(len(self.ids)))
        ends = np.searchsorted(qa, np.arange(len(self.ids)), side="right")
        names = self.field.ids
        for i in map(int, np.flatnonzero(counts)):
            idx = qs[starts[i]:ends[i]]
            pts = tuple(zip(*self.field.samples[idx].T.tolist(),
                            [names[o] for o in self.field.owner[idx].tolist()], strict=True))
            scans[i] = wire.Scan(self.ids[i], k, t, pts, bodies[i])
        states = [wire.State(a, k, t, float(c[i, 0]), float(c[i, 1]), float(self.theta[i]), float(self.p[i, 0]),
                             float(self.p[i, 1]), scans[i]) for i, a in enumerate(self.ids)]
        return TickOut(clock, truth, states)

    def held_bodies(self) -> list[tuple[tuple[int, float, float], ...]]:
        """Per robot: the held robots (whose agents are gone) within body_range_m of its head point, as
        (agent id, head x, y); none for a robot whose own agent is gone."""
        out: list[tuple[tuple[int, float, float], ...]] = [()] * len(self.ids)
        held = [i for i, a in enumerate(self.ids) if a not in self.alive]
        if not held or len(held) == len(self.ids):
            return out
        hp = self.p[held]  # (H, 2)
        d = np.hypot(*(self.p[:, None, :] - hp[None, :, :]).transpose(2, 0, 1))  # (N, H)
        for i, a in enumerate(self.ids):
            if a in self.alive:
                out[i] = tuple((self.ids[held[j]], float(hp[j, 0]), float(hp[j, 1]))
                               for j in map(int, np.flatnonzero(d[i] <= self.body_range_m)))
        return out

    def apply(self, k: int) -> None:
        """Choose every robot's input for the step k -> k+1 and integrate."""
        hold = max(1, round(self.timing.hold_sim_s / self.s.meta.dt_s))
        self.headings[k] = self.theta.copy()
        for kk in [x for x in self.headings if x < k - hold - 1]:
            del self.headings[kk]
        got = self.cmds.pop(k, {})
        for kk in sorted(x for x in self.cmds if x < k):  # late commands still count as the latest
            late = {i: vw for i, vw in self.cmds.pop(kk).items() if kk > self.held_k[i]}
            if late and kk in self.headings:  # (older than the hold: stale anyway)
                self._hold(kk, late)
        if got:
            self._hold(k, got)
        if self.clock == ClockMode.LOCKSTEP and self.uncommanded_k < 0 and len(got) < len(self.ids):
            self.uncommanded_k = k
        if self.clock == ClockMode.REALTIME:
            live = [self.index[a] for a in self.alive]
            self.expected += len(live)
            self.missed += sum(1 for i in live if i not in got)
        stale = (k - self.held_k) > hold
        self.integrate(np.where(stale[:, None], 0.0, self.held))

    def _hold(self, k: int, cmds: dict[int, np.ndarray]) -> None:
        """Hold the commands (v, ω) of tick k (agent index -> row) as the robots' plant inputs."""
        rows = np.array(list(cmds), dtype=np.int64)
        vw = np.array([cmds[i] for i in rows.tolist()])
        self.held[rows] = self.plant_input(vw, self.headings[k][rows], rows)
        self.held_k[rows] = k

    def plant_input(self, vw: np.ndarray, theta: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The input these robots' plant holds over the step: the head point's velocity u = M(θ_k) [v, ω]
        (eq. 3) at the heading the agent planned from, the zero-order hold of u the in-process engine uses
        (unicycle.through_inputs). vw: (n, 2), theta: (n,), rows: (n,) agent indices -> (n, 2)."""
        return unicycle.head_velocity(vw[:, 0], vw[:, 1], theta, self.l[rows])

    def integrate(self, u: np.ndarray) -> None:
        """Move every robot over one step under its held input (N, 2) (zeros: stopped)."""
        w = self.s.world
        self.p, self.theta = unicycle.step(self.p, self.theta, u, self.l, self.s.meta.dt_s, w.max_speed_mps,
                                           w.max_turn_rate_radps)

    def stats(self) -> dict[str, float]:
        out: dict[str, float] = {"world_overruns": float(self.overruns)}
        if self.latency_ms:
            lat = np.array(self.latency_ms)
            out.update(latency_p50_ms=round(float(np.percentile(lat, 50)), 3),
                       latency_p99_ms=round(float(np.percentile(lat, 99)), 3), latency_samples=float(lat.size))
        if self.uncommanded_k >= 0:
            out.update(uncommanded_from_s=round(self.uncommanded_k * self.s.meta.dt_s, 9))
        if self.clock == ClockMode.REALTIME:
            out.update(missed_deadlines=float(self.missed), deadlines=float(self.expected),
                       missed_deadline_ratio=round(self.missed / self.expected, 5) if self.expected else 0.0)
        return out

    def converged(self) -> bool:
        live = [self.index[a] for a in self.alive]
        if not live:
            return False
        e = errors(self.p[live], np.asarray(self.s.target_m), self.s.offsets[live])
        return bool(e.max() <= self.s.planner.converge_tol_m)
