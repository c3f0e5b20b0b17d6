"""The world's tick logic as a pure state machine (the node contract, reconswarm/net/node.py): no zenoh, no clock.

`WorldNode.step(inputs, now_s)` takes what arrived (liveliness tokens, the commands the process's gate admitted
with the time each arrived, our own session's router link, a signal, what was dropped as invalid) and returns
what to publish, in order: a tick's clock, truth and every robot's state (with its scan), and `Exit(0, end
reason)` once the mission ends. It owns the robots (the plant: simworld/robots.py) and every rule of the world:

- membership: an agent is alive while its token is there AND its commands keep coming (a token alone can be
  forged; reconswarm/net/trust/membership.py): a token that goes is gone `token_confirm_s` later; a token whose agent
  sends nothing stops holding a lockstep tick up after a grace; while our own session has no router nobody is
  judged; after the world itself stalled, tokens that flap are kept for a while;
- readiness barrier: the mission starts when every agent of the scenario and the monitor are up;
  past `start_timeout_s` it fails naming who is missing;
- lockstep: tick k advances when the command for k of every agent the clock announced is in; a tick
  that has waited `republish_s` is published again (data lost in an outage is sent again); after
  `step_timeout_s` the missing robots are held, and an agent that let the step time out `strikes`
  times in a row is not waited for until it commands again;
- realtime: tick k advances at t0 + (k+1) dt / speed on the latest commands (missed deadlines and
  state-to-command latency, from the step that published the tick to the command's arrival, are counted);
- a robot whose command is missing is held (last command) for `hold_sim_s`, then stopped;
- with no agent reachable the world holds for `no_agents_grace_s`, then ends the mission;
- the world itself not stepped for `self_stall_s` (SIGSTOP, a starved machine): nobody was late, its waits
  start afresh.

The process (simworld/process.py) routes samples to these inputs and puts the outputs on the wire.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum, auto

import numpy as np

from reconswarm.errors import ProcessFailure
from reconswarm.net.node import Exit, Invalid, Role, RouterReach, Stop, Token
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.trust.membership import Membership, Policy
from reconswarm.net.wire import wire
from reconswarm.net.wire.wire import ClockMode
from reconswarm.scenario.model import Scenario
from simworld.robots import Robots

log = logging.getLogger("reconswarm.simworld")


class Phase(Enum):
    READY = auto()  # waiting for everyone (the readiness barrier)
    TICK = auto()  # about to publish tick k
    WAIT_COMMANDS = auto()  # lockstep: tick k published, waiting for its commands
    WAIT_DUE = auto()  # realtime: tick k published, waiting for its deadline
    NO_AGENTS = auto()  # nobody reachable: holding the world
    DONE = auto()


@dataclass(frozen=True)
class Command:
    """A command the process's gate admitted (from agent i's own session, bounded; in ROS 2 mode a cmd_vel, of the
    tick the port dates it to: simworld/ros2_io.py) and the wall time it arrived (its latency counts to then)."""

    cmd: wire.Cmd
    at_s: float


WorldInput = Token | Command | RouterReach | Stop | Invalid
WorldOutput = wire.Clock | wire.Truth | wire.State | Exit


@dataclass
class _Turn:
    """What one turn of the machine gives: messages to put, when to be stepped next, the end reason if it ended."""

    out: list[WorldOutput] = field(default_factory=list)
    wake_s: float = 0.0
    ended: str | None = None


class WorldNode:
    def __init__(self, s: Scenario, clock: ClockMode = ClockMode.LOCKSTEP, speed: float = 1.0,
                 timing: Timing = TIMING, robots: Robots | None = None) -> None:
        self.s, self.clock, self.speed, self.timing = s, clock, speed, timing
        self.robots = Robots(s, timing.hold_sim_s) if robots is None else robots
        self.ids, self.index = self.robots.ids, self.robots.index
        # Who is alive (the one place the world decides it): a token AND own commands (the world's policy: a token
        # without commands does not hold a lockstep tick up beyond a grace longer than an agent's own wait).
        self.members = Membership(Policy.world(timing))
        self.alive: set[int] = set()
        self.monitor = False
        self.stopping = False  # a signal came: the mission ends at the next tick
        self.strikes: dict[int, int] = {}  # lockstep: consecutive step timeouts of each agent
        self.unresponsive: set[int] = set()  # not waited for until they command again
        self.rejected = 0  # messages dropped as invalid (reported on the clock)
        self.pub_time: dict[int, float] = {}  # tick -> wall time of the step that published it (latest)
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
        self.linked, self.unlinked_at = True, 0.0  # our own session has its router (see _link)
        self.wake_s: float | None = None  # when the last step asked to be stepped again

    # ------------------------------------------------------------------------------------- the contract

    def step(self, inputs: Sequence[WorldInput], now_s: float) -> list[WorldOutput]:
        """Take what arrived, decide who is alive, and advance as far as that allows at now_s: at most one tick
        published or stepped per call."""
        if self.last_step_s is not None and self.stalled(now_s):
            self._own_stall(now_s, now_s - self.last_step_s)
        self.last_step_s = now_s
        for m in inputs:
            self._take(m, now_s)
        self._sync(now_s)
        turn = self._machine(now_s)
        self.wake_s = turn.wake_s
        return turn.out if turn.ended is None else [*turn.out, Exit(0, turn.ended)]

    def wake_at_s(self) -> float | None:
        return self.wake_s

    def awaiting(self, now_s: float) -> int | None:
        """How many messages to wait for before stepping again (or until `wake_at_s`): the commands still missing
        while a lockstep tick waits for them; None while realtime waits for its due time; 1 otherwise."""
        if self.phase == Phase.WAIT_COMMANDS:
            return max(1, len(self.missing()))
        return None if self.phase == Phase.WAIT_DUE else 1

    # ------------------------------------------------------------------------------------- inputs

    def _take(self, m: WorldInput, now_s: float) -> None:
        sim = self.k * self.s.meta.dt_s
        if isinstance(m, Command):
            if m.cmd.id not in self.index:  # (the gate admits only the scenario's agents)
                self.rejected += 1
                return
            self.members.data(m.cmd.id, m.at_s, sim)
            self._command(m.cmd, m.at_s)
        elif isinstance(m, Token):
            if m.role is Role.MONITOR:
                self.monitor = m.up
            elif m.role is Role.AGENT and m.agent in self.index:
                self.members.token(m.agent, m.up, now_s, sim)
        elif isinstance(m, RouterReach):
            self.members.link(m.up, now_s, sim)
            self._link(m.up, now_s)
        elif isinstance(m, Stop):
            self.stopping = True
        elif isinstance(m, Invalid):
            self.rejected += 1

    def _command(self, c: wire.Cmd, at_s: float) -> None:
        self.robots.command(c.id, c.k, c.v_mps, c.omega_radps)
        if c.id in self.unresponsive:
            self.unresponsive.discard(c.id)
            self.strikes.pop(c.id, None)
            log.info("agent %d commands again", c.id)
        sent = self.pub_time.get(c.k)
        if sent is not None and self.clock == ClockMode.REALTIME:
            self.latency_ms.append((at_s - sent) * 1000.0)

    def _link(self, up: bool, now_s: float) -> None:
        """Our own session lost its router (up=False) or has one again. Meanwhile nobody is reachable: the world
        holds as with no agent (ending the mission after `no_agents_grace_s`), no robot is stepped without its
        command and nobody is lost; realtime's schedule then moves on by the time it held."""
        if up != self.linked:
            self.linked = up
            if up:
                self.t0 += now_s - self.unlinked_at
            else:
                self.unlinked_at = now_s

    def _sync(self, now_s: float) -> None:
        """Who is alive now, by the membership rule (token AND own commands), with a tick's wait counted."""
        sim = self.k * self.s.meta.dt_s
        if self.started:
            self.members.start(now_s, sim)
        if self.phase is Phase.WAIT_COMMANDS and self.deadline_s is not None:  # (since the tick went out)
            for aid in self.missing():
                self.members.awaited(aid, self.deadline_s - self.timing.step_timeout_s, now_s)
        for aid in self.ids:
            up = self.members.alive(aid, now_s, sim)
            if up and aid not in self.alive:
                self.alive.add(aid)
            elif not up and aid in self.alive:
                self.alive.discard(aid)
                log.warning("agent %d is gone", aid)

    # ------------------------------------------------------------------------------------- the machine

    def _machine(self, now_s: float) -> _Turn:
        stopping = self.stopping
        if not self.linked and not stopping and self.phase in (Phase.WAIT_COMMANDS, Phase.WAIT_DUE):
            self.phase = Phase.TICK  # (tick k is published again once the link is back)
        if self.phase == Phase.READY:
            return self._ready(now_s)
        if self.phase == Phase.TICK:
            return self._tick(now_s)
        if self.phase == Phase.NO_AGENTS:
            if self.alive and self.linked:
                log.info("agents reachable again: %s", sorted(self.alive))
                return self._publish_tick(now_s, "")
            if stopping or now_s >= self._deadline(now_s):
                return self._publish_tick(now_s, "no agents")
            return _Turn([], self._deadline(now_s))
        if self.phase == Phase.WAIT_COMMANDS:
            return self._wait_commands(now_s)
        if self.phase == Phase.WAIT_DUE:
            if stopping or now_s >= self._deadline(now_s):
                return self._advance(now_s)
            return _Turn([], self._deadline(now_s))
        return _Turn([], now_s, "stopped")

    def stalled(self, now_s: float) -> bool:
        """The world itself was not stepped for `self_stall_s` (its runtime steps it every 50 ms at most)."""
        return self.last_step_s is not None and now_s - self.last_step_s >= self.timing.self_stall_s

    def _own_stall(self, now_s: float, gap_s: float) -> None:
        """The world itself did not run for gap_s (SIGSTOP, a starved machine): its session may have lapsed, and
        tokens that go within its policy's `stall_settle_s` (peer_silent_s) are kept (they come back as the
        sessions reconnect). Nobody was late, so no step times out for it: lockstep waits afresh for the agents it
        waited for and publishes the tick again now; realtime shifts its schedule."""
        self.members.settle(now_s + self.members.policy.stall_settle_s)
        if not self.started:
            return
        log.warning("simworld itself was stalled for %.1f s at tick %d: waiting afresh", gap_s, self.k)
        if self.phase == Phase.WAIT_COMMANDS:
            self.deadline_s, self.again_s, self.resumed = now_s + self.timing.step_timeout_s, now_s, True
        elif self.deadline_s is not None:
            self.deadline_s += gap_s
        self.t0 += gap_s

    def _deadline(self, now_s: float) -> float:
        return now_s if self.deadline_s is None else self.deadline_s

    def _ready(self, now_s: float) -> _Turn:
        if self.deadline_s is None:
            self.deadline_s = now_s + self.timing.start_timeout_s
        if self.stopping:
            self.phase = Phase.DONE
            return _Turn([], now_s, "stopped")
        if self.monitor and set(self.ids) <= self.alive:
            log.info("all up: mission starts")
            self.phase, self.t0, self.deadline_s, self.started = Phase.TICK, now_s, None, True
            return _Turn([], now_s)
        if now_s > self.deadline_s:
            missing = [f"agent {a}" for a in self.ids if a not in self.alive]
            if not self.monitor:
                missing.append("monitor")
            raise ProcessFailure(f"simworld: not up after {self.timing.start_timeout_s:.0f} s: {', '.join(missing)}")
        return _Turn([], self.deadline_s)

    def _tick(self, now_s: float) -> _Turn:
        reason = ""
        if self.robots.converged(self.alive):
            reason = "converged"
        elif self.k == self.n_ticks:
            reason = "duration"
        elif self.stopping:
            reason = "stopped"
        elif not self.alive or not self.linked:
            log.warning("no agent is reachable%s: holding the world for up to %.0f s",
                        "" if self.linked else " (our own link to the router is gone)", self.timing.no_agents_grace_s)
            self.phase, self.deadline_s = Phase.NO_AGENTS, now_s + self.timing.no_agents_grace_s
            return _Turn([], self.deadline_s)
        return self._publish_tick(now_s, reason)

    def _publish_tick(self, now_s: float, reason: str) -> _Turn:
        out = self.tick_out(self.k, reason, now_s)
        if reason:
            self.phase = Phase.DONE
            return _Turn(out, now_s, reason)
        if self.clock == ClockMode.LOCKSTEP:
            self.waiting_for = set(self.alive) - self.unresponsive
            self.phase, self.deadline_s = Phase.WAIT_COMMANDS, now_s + self.timing.step_timeout_s
            self.again_s = now_s + self.timing.republish_s
            return _Turn(out, min(self.deadline_s, self.again_s))
        due = self.t0 + (self.k + 1) * self.period_s
        if now_s > due:
            self.overruns += 1
        self.phase, self.deadline_s = Phase.WAIT_DUE, due
        return _Turn(out, due)

    def missing(self) -> list[int]:
        """Lockstep: agents the current tick still waits for."""
        got = self.robots.cmds.get(self.k, {})
        live = self.waiting_for if self.resumed else self.waiting_for & self.alive
        return sorted(a for a in live if self.index[a] not in got)

    def _wait_commands(self, now_s: float) -> _Turn:
        missing = self.missing()
        if not missing:
            self.strikes.clear()
            return self._advance(now_s)
        if self.stopping or now_s >= self._deadline(now_s):
            log.warning("tick %d: no command from %s within %.1f s: holding their robots", self.k, missing,
                        self.timing.step_timeout_s)
            for a in missing:
                self.strikes[a] = self.strikes.get(a, 0) + 1
                if self.strikes[a] >= self.timing.strikes:
                    self.unresponsive.add(a)
                    log.warning("agent %d is unresponsive: not waiting for it until it commands again", a)
            return self._advance(now_s)
        out: list[WorldOutput] = []
        if now_s >= self.again_s:
            log.info("tick %d: still waiting for agents %s: publishing the tick again", self.k, missing)
            out = self.tick_out(self.k, "", now_s)
            self.again_s = now_s + self.timing.republish_s
        return _Turn(out, min(self._deadline(now_s), self.again_s))

    def _advance(self, now_s: float) -> _Turn:
        got = self.robots.apply(self.k)
        if self.clock == ClockMode.LOCKSTEP and self.uncommanded_k < 0 and len(got) < len(self.ids):
            self.uncommanded_k = self.k
        if self.clock == ClockMode.REALTIME:
            live = [self.index[a] for a in self.alive]
            self.expected += len(live)
            self.missed += sum(1 for i in live if i not in got)
        self.k += 1
        self.phase, self.deadline_s, self.resumed = Phase.TICK, None, False
        return _Turn([], now_s)

    # ------------------------------------------------------------------------------------- what a tick says

    def tick_out(self, k: int, reason: str, now_s: float) -> list[WorldOutput]:
        """Tick k's clock (the end of the mission, with the statistics, if `reason`), states and truth, published
        at now_s (state-to-command latency counts from then): the agents' data first, the truth (the monitor's,
        beside the tick's path) last."""
        end = bool(reason)
        clock = wire.Clock(k, k * self.s.meta.dt_s, tuple(sorted(self.alive)), self.clock,
                           self.speed if self.clock == ClockMode.REALTIME else 0.0, end, reason, self.rejected,
                           self.stats() if end else {})
        truth, states = self.robots.observe(k, self.alive)
        self.pub_time[k] = now_s
        while (oldest := next(iter(self.pub_time))) < k - 1000:  # (oldest first: ticks go out in order)
            del self.pub_time[oldest]
        return [clock, *states, truth]

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
