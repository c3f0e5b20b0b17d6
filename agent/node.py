"""One agent's protocol logic as a pure state machine (the node contract, reconswarm/net/node.py): `step(batch,
now_s)` takes the messages that arrived and the runtime's wall time, returns what to publish (a beacon, an obstacle
set, a plan for its host's law) or to do (listen to other cells, open a new session, exit). AgentBrain is the math
it calls.

When a tick is acted on is the clock's pace (`pace`): agent/lockstep.py (each tick once all its data is in) or
agent/realtime.py (the newest state, at once or at a deadline). A lost peer stays where last seen or where the
world's scan reports it held; a live one out of our cells is dropped.
A new session of its process (`reconnected`) keeps the node: peers, lost peers, knowledge, revisions, escape state.
Its router link lost (or changed) mid-mission in lockstep, what was in flight to it is lost and nobody sends it
again: the next tick it acts on is a guess (`guessed_k`).
What it heard is agent/heard.py's. The law is its host's, for a lone agent as for many: the node returns its
tick's `Plan` and takes its command back as `Law` (agent/host.py computes the law of every plan of a round at once).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from collections.abc import Set as AbstractSet

import numpy as np

from agent.brain import AgentBrain, Body
from agent.heard import Heard
from agent.lockstep import LOCKSTEP, Lockstep
from agent.messages import Input, Law, Output
from agent.neighbours import Cells, Neighbourhood
from agent.realtime import REALTIME, Realtime
from agent.sets import PeerSets, own_set, scan_sets
from agent.watch import watch
from reconswarm.net.node import Exit, Invalid, Role, RouterReach, Stop, Token
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.trust.membership import Policy, silent
from reconswarm.net.wire import wire
from reconswarm.scenario.model import Scenario

log = logging.getLogger("reconswarm.agent")


class AgentNode:
    def __init__(self, s: Scenario, agent_id: int, now_s: float, timing: Timing = TIMING) -> None:
        self.s, self.id, self.timing, self.policy = s, agent_id, timing, Policy.agent(timing)
        self.planning = -1  # the tick of our plan out, whose `Law` our host computes (-1: none)
        self.brain = AgentBrain(s, agent_id)
        self.nb = Neighbourhood(s, agent_id)  # our cells and whom a tick waits for (agent/neighbours.py)
        self.radius = float(self.brain.r[0])
        self.rejected = 0  # messages dropped so far (in our reports)
        self.h = Heard(agent_id)  # the states, scans, clocks, beacons we heard by tick, who is alive (agent/heard.py)
        ps = self.peer_sets = PeerSets()  # peers' sets by revision, and the revisions merged (agent/sets.py)
        self.sets, self.merged, self.merged_union = ps.sets, ps.merged, ps.merged_union
        self.k, self.beacon_sent = -1, -1  # last tick commanded, last tick announced
        self.wait_since: float | None = None
        self.guessed_k = -1  # lockstep: the first tick acted on without all its data (-1: none)
        self.guess = ""  # why the tick about to be acted on lacks data ("": it does not)
        self.pace: Lockstep | Realtime = LOCKSTEP  # when a tick is acted on: the clock's mode says
        self.period_s, self.now = 0.0, now_s  # (now: the wall time of the latest step or awaiting call)
        self.act_at: float | None = None
        self.last_clock, self.world_at, self.ended = now_s, now_s, False  # (world_at: its latest clock or our state)
        self.clock_in: wire.Clock | None = None  # the latest clock received: an end stands if nothing came after it
        self.world_gone = False  # the world's token went away and nothing came from it since (a stalled world)
        self.link_lost = False  # lockstep: our router link went (or changed) mid-mission since our last tick
        self.unlinked = False  # our session has no router (nobody's token that goes is judged meanwhile)
        self.started = False  # the mission began (first clock): the watches run from then on
        self.last_cmd: wire.Cmd | None = None
        self.last_act = self.acted = now_s  # wall time of our latest command, re-sent or not (acted: of a new tick)
        self.waited: dict[tuple[int, int, bool], tuple[wire.Clock | None, frozenset[int]]] = {}  # `expected`'s
        self.linked: tuple[int, dict[int, int]] = (-1, {})  # (tick, linked peer -> its set's revision)
        self.beacon_again, self.again_n, self.told_waiting = 0.0, 0, 0.0  # announce again at; how often; logged
        self.out: list[Output] = []
        self._awaited: tuple[float, int | None] = (-math.inf, None)  # `awaiting`'s: when, and what it said
        self._announce_set = False  # after a new session: publish our obstacle set again (its cache is new)

    # ------------------------------------------------------------------------------------- interface

    def step(self, batch: Iterable[Input], now_s: float) -> list[Output]:
        """Take the messages that arrived, advance as far as the data allows, watch the world and our
        own progress. Returns what to publish or do, in order."""
        self.out, self.now, self._awaited = [], now_s, (-math.inf, None)
        if self._announce_set:
            self._announce_set = False
            self.out.append(self.obstacle_set(max(self.k, 0)))
        for m in batch:
            if isinstance(m, Stop):  # (a signal: we leave at once, our report says what happened)
                return [Exit(0, "stopped")]
            self._take(m, now_s)
        if self.h.going and not self.unlinked:
            self.h.confirm(now_s, self.timing.token_confirm_s)
        self._advance(now_s)
        if self.planning < 0:  # (a plan out: the watch waits for its law)
            watch(self, now_s)  # (the safety nets: agent/watch.py)
        out, self.out = self.out, []
        return out

    def cells(self) -> Cells:
        """The cells a session must declare for us before any step (our link and host ask; then `Cells` outputs)."""
        return self.nb.session_cells()

    def reconnected(self, now_s: float) -> None:
        """A new session: `resubscribe_s` to bring the commands back; our set in its cache at the next step."""
        self.last_act = self.acted = now_s
        self._announce_set = self.brain.rev > 0

    def awaiting(self, now_s: float) -> int | None:
        """How many more messages the next tick needs at least (the runtime sleeps until that many are in, or its
        own state, or a timeout); None: only our own state lets us act. Lockstep: kept until our next step, or for
        `agent_poll_s` (meanwhile only a peer's silence could lower it)."""
        if now_s - self._awaited[0] < self.timing.agent_poll_s:
            return self._awaited[1]
        self._awaited = (now_s if self.pace.holds_awaiting else -math.inf, None)
        self.now = now_s
        k = self.pace.next_tick(self)
        st = self.h.states.get(k)
        if st is None or k <= self.k:
            return None
        fresh, clock, heard = self.h.beacons.get(k, {}), self.h.clocks.get(k), self.h.heard
        waited = self.expected(k, clock)
        need = sum(1 for a in waited if a not in fresh and not silent(self.policy, heard.get(a, now_s), now_s))
        need += self.pace.more_needed(self, k, clock, fresh, waited)
        self._awaited = (self._awaited[0], max(1, need))
        return self._awaited[1]

    def wake_at_s(self) -> float | None:
        """Realtime: when to step at the latest even if nothing arrives (None: no deadline)."""
        return self.act_at

    # ----------------------------------------------------------------------------------------- input

    def _take(self, m: Input, now: float) -> None:
        if isinstance(m, wire.Beacon):  # (most of what arrives: first)
            self.h.beacon(m, now)
            if m.k <= self.k and self.guessed_k < 0 and self.nb.intruder(m.k, m):  # too late: we acted without it
                self.guessed_k = m.k
                log.warning("agent %d: tick %d: %s; lockstep is no longer deterministic", self.id, m.k,
                            self.nb.unexpected(m))
        elif isinstance(m, Token) and m.role is Role.AGENT and m.agent is not None:
            self.h.token(m.agent, m.up, now)
            if m.up:
                self.nb.peer_joined(m.agent, self.k >= 0)
        elif isinstance(m, Token) and m.role is Role.WORLD:
            if m.up:
                self._world_back(now)
            else:
                self.world_gone = True
        elif isinstance(m, Invalid):
            self.rejected += 1
        elif isinstance(m, RouterReach):  # what was in flight to us meanwhile is lost: nobody sends it again
            self.link_lost |= self.pace.loses_in_flight(self)
            self.unlinked = not m.up  # (its tokens went with it: judged only once they had time to come back)
            self.h.hold(now + (self.timing.relink_settle_s if m.up else 0.0))
            if m.up and self.beacon_sent in self.h.states:  # our newest beacon may have been lost with the link:
                self.out.append(self.beacon(self.h.states[self.beacon_sent]))  # peers place us by it
        elif isinstance(m, wire.Clock):
            self._world_back(now)
            self.h.clock(m, now)
            self.clock_in, self.last_clock = m, now
            self.pace = REALTIME if m.mode == "realtime" else LOCKSTEP
            self.period_s = self.s.meta.dt_s / m.speed if m.speed > 0 else 0.0
        elif isinstance(m, wire.State):
            if m.id != self.id:
                return
            self._world_back(now)
            if m.k == self.k and self.last_cmd is not None:  # the world missed a command: ours again (we hear it)
                self.out.append(self.last_cmd)
                self.last_act = now
                return
            self.h.states[m.k] = m
            if m.scan is not None:
                self._take(m.scan, now)
            self.pace.on_state(self, now)
        elif isinstance(m, wire.Scan):  # (in its state; in ROS 2 mode on its own key)
            if m.id == self.id:
                self.h.scan(m, self.nb.radius)
        elif isinstance(m, wire.ObstacleSet):
            self.peer_sets.add(m)
        elif isinstance(m, Law) and m.k == self.planning:
            self.planning = -1
            self._command(m.k, m.v_mps, m.omega_radps, now)

    def _world_back(self, now: float) -> None:
        """The world speaks (a clock, our state). Back from a stall (`quiet`), every wait starts now: for a command
        (before a new session), for a tick's data, and each peer's silence (nobody had a state to announce)."""
        if self.quiet(now):
            self.world_gone, self.last_act, self.acted = False, max(self.last_act, now), max(self.acted, now)
            self.h.silent_since(now)
            self.wait_since = None if self.wait_since is None else max(self.wait_since, now)
        self.world_at = now

    def quiet(self, now: float) -> bool:
        """The world stalls (lockstep: its token is gone, or it said nothing for `world_quiet_s`; realtime: its token
        is gone)."""
        return self.pace.quiet(self, now)

    # --------------------------------------------------------------------------------------- planning

    def expected(self, k: int, clock: wire.Clock | None) -> AbstractSet[int]:
        """The live peers tick k waits for (agent/lockstep.py, agent/realtime.py)."""
        return self.pace.expected(self, k, clock)

    def _peers(self, k: int) -> tuple[list[Body], list[Body]]:
        """Whom tick k plans with, (live, lost). Live: every beacon of k; the latest of a peer it waited for but
        lacks (a guess); not a live peer that may not matter at k (realtime: not heard lately, unless our scan
        says its robot is held near us). Lost (not `Heard.living`, which a forged token does not fool): where
        their robots stopped (latest beacon, or scan)."""
        fresh, st = self.h.beacons.get(k, {}), self.h.states[k]
        clock = self.h.clocks.get(k) or self.h.newest_clock()  # (realtime: the newest)
        living, wanted = self.h.living(clock), self.pace.wanted(self, k, (st.px, st.py))
        live, lost = list[Body](), list[Body]()  # (the beacons themselves: each names its peer, head point, radius)
        for a, b in self.h.last_seen.items():
            if (f := fresh.get(a)) is not None or (a in living and a in wanted):
                live.append(f if f is not None else b)
            elif a not in living:
                lost.append(b)
        return live, lost

    def beacon(self, st: wire.State) -> wire.Beacon:
        return wire.Beacon(self.id, st.k, st.t, st.px, st.py, self.radius, self.brain.rev)

    def link(self, k: int, p: np.ndarray) -> None:
        """Which peers' sets tick k merges: those within link range of p by their beacons at k."""
        fresh = self.h.beacons.get(k, {})
        self.linked = (k, {a: fresh[a].rev for a in self.brain.linked_at(p, fresh)})

    def move(self, k: int, st: wire.State) -> None:
        """Our state of tick k is in: our cells follow us (before our beacon, long before our command); in a
        new home cell our obstacle set is put again (its cache there is new)."""
        old = self.nb.home
        cells = self.nb.on_state(k, (st.px, st.py))
        if cells is not None:
            self.out.append(cells)
            if cells.home != old and self.brain.rev:
                self.out.append(self.obstacle_set(max(self.k, 0)))

    def act(self, k: int, now: float) -> None:
        st = self.h.states[k]
        self.pace.check_late(self, k)
        self.link_lost = False
        if self.guess and self.guessed_k < 0:
            self.guessed_k = k
            log.warning("agent %d: tick %d: %s: acting without them; lockstep is no longer deterministic",
                        self.id, k, self.guess)
        self.guess = ""
        p = np.array([st.px, st.py])
        peers, lost = self._peers(k)
        linked = self.pace.linked_sets(self, k, p, peers, lost)
        if self.k < 0 and k > 0:  # joining a mission under way: catch up on everything peers have cached
            linked = self.peer_sets.newest()
            log.info("agent %d: joining at tick %d; cached obstacle sets from agents %s: %s", self.id, k,
                     sorted(linked), sorted({o for revs in self.sets.values() for v in revs.values() for o in v}))
        shared = self.peer_sets.unmerged(linked, self.merged)
        swarm = None if self.brain.leader is None else self.peer_sets.unmerged(
            self.pace.swarm_revisions(self, k), self.merged_union)
        scan = scan_sets(self.h.scans, self.k + 1 if self.k >= 0 else k, k)
        plan = self.brain.plan(k, p, scan, peers, shared, swarm, lost, st.theta)
        if plan.grew:
            self.out.append(self.obstacle_set(k))
        self.planning = k  # our host computes the law with its other agents' plans, then hands it to us
        self.out.append(plan)

    def _command(self, k: int, v_mps: float, omega_radps: float, now: float) -> None:
        self.last_cmd = wire.Cmd(self.id, k, v_mps, omega_radps)  # (v, ω) at our heading θ_k
        self.waited.clear()  # (tick k's)
        self.out.append(self.last_cmd)
        cells = self.nb.after_command(k)
        if cells is not None:
            self.out.append(cells)
        self.last_act, self.acted, self.k, self.wait_since = now, now, k, None
        if k % 20 == 0:
            self._prune(k)

    def waiting_for(self) -> str:
        """What the next tick still lacks (for the log while we wait)."""
        k = self.k + 1
        waited = self.expected(k, self.h.clocks.get(k)) if k in self.h.states else frozenset()
        return self.h.lacks(k, waited, {a: rev for a, rev in self.linked[1].items() if rev}, self.sets)

    def obstacle_set(self, k: int) -> wire.ObstacleSet:
        return own_set(self.id, k, self.brain.rev, self.brain.obstacle_sets())

    def _prune(self, k: int) -> None:
        self.h.prune(k)
        self.nb.prune(k)
        p, stale_k = (self.h.states[k].px, self.h.states[k].py), k - round(self.policy.fresh_s / self.s.meta.dt_s)
        living = self.pace.living_at(self, k)
        self.h.forget_stale(lambda b: self.nb.audible(p, b), living, stale_k)
        self.peer_sets.prune(self.brain.leader is not None)

    def _advance(self, now: float) -> None:
        """Act on every tick the data allows, at the clock's pace (none while our plan waits for its law)."""
        if self.planning < 0:
            self.pace.advance(self, now)
