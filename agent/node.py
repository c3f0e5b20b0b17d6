"""One agent's protocol logic as a pure state machine (the node contract, reconswarm/net/node.py): `step(batch,
now_s)` takes the messages that arrived and the runtime's wall time, returns what to publish (a beacon, an obstacle
set, a command) or to do (listen to other cells, open a new session, exit). AgentBrain is the math it calls.

Lockstep (the clock says so): at tick k the agent waits for its state (its scan inside), announces its beacon
(with the revision of its obstacle set at k-1), waits for the beacons of the live agents that may matter
at k (agent/neighbours.py: the cells it listens to and its wait set; every live agent for the virtual
leader) and the obstacle sets of those within link range (all for the virtual leader), then plans and
commands. Realtime: it acts shortly after each new state on whatever it has (latest beacons, sets). A lost
peer stays where last seen or where the world's scan reports it held; a live one out of our cells is dropped.
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
from agent.messages import Input, Law, Output
from agent.neighbours import Cells, Neighbourhood
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
        self._guess = ""  # why the tick about to be acted on lacks data ("": it does not)
        self.mode = "lockstep"
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
        self._waited: dict[tuple[int, int, bool], tuple[wire.Clock | None, frozenset[int]]] = {}  # `_expected`'s
        self._linked: tuple[int, dict[int, int]] = (-1, {})  # (tick, linked peer -> its set's revision)
        self.beacon_again, self._again_n, self.told_waiting = 0.0, 0, 0.0  # announce again at; how often; logged
        self._out: list[Output] = []
        self._awaited: tuple[float, int | None] = (-math.inf, None)  # `awaiting`'s: when, and what it said
        self._announce_set = False  # after a new session: publish our obstacle set again (its cache is new)

    # ------------------------------------------------------------------------------------- interface

    def step(self, batch: Iterable[Input], now_s: float) -> list[Output]:
        """Take the messages that arrived, advance as far as the data allows, watch the world and our
        own progress. Returns what to publish or do, in order."""
        self._out, self.now, self._awaited = [], now_s, (-math.inf, None)
        if self._announce_set:
            self._announce_set = False
            self._out.append(self._obstacle_set(max(self.k, 0)))
        for m in batch:
            if isinstance(m, Stop):  # (a signal: we leave at once, our report says what happened)
                return [Exit(0, "stopped")]
            self._take(m, now_s)
        if self.h.going and not self.unlinked:
            self.h.confirm(now_s, self.timing.token_confirm_s)
        self._advance(now_s)
        if self.planning < 0:  # (a plan out: the watch waits for its law)
            watch(self, now_s)  # (the safety nets: agent/watch.py)
        out, self._out = self._out, []
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
        self._awaited = (now_s if self.mode != "realtime" else -math.inf, None)
        newest, self.now = max(self.h.states, default=-1), now_s
        k = self.k + 1 if self.mode != "realtime" and self.k >= 0 and (self.k + 1) in self.h.states else newest
        st = self.h.states.get(k)
        if st is None or k <= self.k:
            return None
        fresh, clock, heard = self.h.beacons.get(k, {}), self.h.clocks.get(k), self.h.heard
        waited = self._expected(k, clock)
        need = sum(1 for a in waited if a not in fresh and not silent(self.policy, heard.get(a, now_s), now_s))
        if self.mode != "realtime":
            need += self.nb.also_heard(self.h.alive, self.h.beacons.get(k - 1, {}), fresh, waited)
            need += clock is None
            if self._linked[0] == k:
                need += sum(1 for a, rev in self._linked[1].items() if rev and rev not in self.sets.get(a, ()))
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
            self.link_lost |= self.started and self.mode == "lockstep" and not self.ended
            self.unlinked = not m.up  # (its tokens went with it: judged only once they had time to come back)
            self.h.hold(now + (self.timing.relink_settle_s if m.up else 0.0))
            if m.up and self.beacon_sent in self.h.states:  # our newest beacon may have been lost with the link:
                self._out.append(self._beacon(self.h.states[self.beacon_sent]))  # peers place us by it
        elif isinstance(m, wire.Clock):
            self._world_back(now)
            self.h.clock(m, now)
            self.clock_in, self.last_clock = m, now
            self.mode = m.mode
            self.period_s = self.s.meta.dt_s / m.speed if m.speed > 0 else 0.0
        elif isinstance(m, wire.State):
            if m.id != self.id:
                return
            self._world_back(now)
            if m.k == self.k and self.last_cmd is not None:  # the world missed a command: ours again (we hear it)
                self._out.append(self.last_cmd)
                self.last_act = now
                return
            self.h.states[m.k] = m
            if m.scan is not None:
                self._take(m.scan, now)
            if self.mode == "realtime":
                self.act_at = now + self.timing.realtime_act_fraction * self.period_s
        elif isinstance(m, wire.Scan):  # (in its state; in ROS 2 mode on its own key)
            if m.id == self.id:
                self.h.scan(m, self.nb.radius)
        elif isinstance(m, wire.ObstacleSet):
            self.peer_sets.add(m)
        elif isinstance(m, Law) and m.k == self.planning:
            self.planning = -1
            self._command(m.k, m.v_mps, m.omega_radps, now)

    def _world_back(self, now: float) -> None:
        """The world speaks (a clock, our state). Back from a stall (`_quiet`), every wait starts now: for a command
        (before a new session), for a tick's data, and each peer's silence (nobody had a state to announce)."""
        if self._quiet(now):
            self.world_gone, self.last_act, self.acted = False, max(self.last_act, now), max(self.acted, now)
            self.h.silent_since(now)
            self.wait_since = None if self.wait_since is None else max(self.wait_since, now)
        self.world_at = now

    def _quiet(self, now: float) -> bool:
        """The world stalls: its token is gone, or (lockstep) it said nothing for `world_quiet_s`."""
        return self.world_gone or (self.mode != "realtime" and now - self.world_at > self.timing.world_quiet_s)

    # --------------------------------------------------------------------------------------- planning

    def _expected(self, k: int, clock: wire.Clock | None) -> AbstractSet[int]:
        """The live peers tick k waits for: those that may matter (agent/neighbours.py) and the world counts alive
        at k (lockstep: kept until the clock or a token changes); realtime: those whose latest beacon may matter."""
        p = (self.h.states[k].px, self.h.states[k].py)
        if self.mode == "realtime":
            return self.nb.near_now(p, self._lately(), self.h.last_seen)
        key = (k, self.h.tokens, clock is None)
        if (got := self._waited.get(key)) is None or got[0] is not clock:
            self.nb.own.setdefault(k, p)
            prev = self.h.beacons.get(k - 1, {})
            got = self._waited[key] = (clock, self.nb.wait_set(k, self.h.living(clock), prev, self.h.last_seen))
        return got[1]

    def _peers(self, k: int) -> tuple[list[Body], list[Body]]:
        """Whom tick k plans with, (live, lost). Live: every beacon of k; the latest of a peer it waited for but
        lacks (a guess); not a live peer that may not matter at k (realtime: not heard lately, unless our scan
        says its robot is held near us). Lost (not `Heard.living`, which a forged token does not fool): where
        their robots stopped (latest beacon, or scan)."""
        fresh, st = self.h.beacons.get(k, {}), self.h.states[k]
        clock = self.h.clocks.get(k) or self.h.newest_clock()  # (realtime: the newest)
        rt, p, living = self.mode == "realtime", (st.px, st.py), self.h.living(clock)
        held = {a for a, _x, _y in sc.bodies} if rt and (sc := self.h.scans.get(k)) is not None else set()
        wanted = self._expected(k, None) if not rt else self._lately() | held
        live, lost = list[Body](), list[Body]()  # (the beacons themselves: each names its peer, head point, radius)
        for a, b in self.h.last_seen.items():
            if (f := fresh.get(a)) is not None or (a in living and a in wanted and (
                    not rt or a in held or self.nb.audible(p, b))):
                live.append(f if f is not None else b)
            elif a not in living:
                lost.append(b)
        return live, lost

    def _lately(self) -> set[int]:
        return self.nb.heard_lately(self.h.alive, self.h.heard, self.now, self.period_s, self.policy.lately_s)

    def _beacon(self, st: wire.State) -> wire.Beacon:
        return wire.Beacon(self.id, st.k, st.t, st.px, st.py, self.radius, self.brain.rev)

    def _link(self, k: int, p: np.ndarray) -> None:
        """Which peers' sets tick k merges: those within link range of p by their beacons at k."""
        fresh = self.h.beacons.get(k, {})
        self._linked = (k, {a: fresh[a].rev for a in self.brain.linked_at(p, fresh)})

    def _ready_lockstep(self, k: int, now: float) -> bool:
        """True once everything tick k needs is in (or the wait timed out)."""
        t = self.timing
        st, clock = self.h.states.get(k), self.h.clocks.get(k)
        if st is None:
            return False
        # Our beacon goes out as soon as our state is in: the peers wait for it (it does not need the clock).
        if self.beacon_sent < k or now > self.beacon_again:  # (again if peers may have lost it)
            if self.beacon_sent < k:
                self._move(k, st)
            self._out.append(self._beacon(st))
            if self.beacon_sent < k:
                self.wait_since, self._again_n = now, 0
            else:
                self._again_n += 1
                if self._again_n == 1 and self.brain.rev:  # stuck: peers may have lost our obstacle set too
                    self._out.append(self._obstacle_set(k))
            self.beacon_sent = k
            # Backing off (0.5, 1, 2 s, ...), the set only once: re-sent every 0.5 s it flooded a stuck N = 64.
            self.beacon_again = now + t.beacon_again_s * 2 ** self._again_n
        # Each way on without some of the tick's data is a guess: the command may differ from the in-process
        # engine's from here on, so the node says so (`guessed_k` in its reports, then the record's summary).
        self._guess, quiet = "", self._quiet(now)  # (none while the world stalls: a peer may lack only its state)
        if clock is None:
            # The tick's clock may have been lost (an outage): after a while, go on with the newest clock's agents.
            first = self.h.state_at.setdefault(k, now)
            if now - first < t.agent_wait_timeout_s or not self.h.clocks or quiet:
                return False
            clock = self.h.clocks[max(self.h.clocks)]
            self._guess = "the tick's clock never came"
        if self.wait_since is not None and now - self.wait_since > t.agent_wait_timeout_s and not quiet:
            self._guess = f"gave up waiting {t.agent_wait_timeout_s:g} s for peers' data"
            return True
        fresh = self.h.beacons.get(k, {})
        # Peers alive by their tokens that may matter at k whose beacon for k is not in: wait, unless one is silent.
        missing = sorted(a for a in self._expected(k, clock) if a not in fresh)  # (not `- fresh.keys()`: many)
        if any(not silent(self.policy, self.h.heard.get(a, now), now) for a in missing) or (quiet and bool(missing)):
            return False
        if missing:
            self._guess = f"agents {missing} alive but silent for {self.policy.fresh_s:g} s"
        if self._linked[0] != k:
            self._link(k, np.array([st.px, st.py]))
        if self.k < 0 and k > 0:  # joining a mission under way: every peer's cached set (any revision) first
            return all(b.rev == 0 or self.sets.get(a) for a, b in fresh.items())
        need = {a: b.rev for a, b in fresh.items()} if self.brain.leader is not None else self._linked[1]
        # A set is there, or nothing to wait for: an empty set (rev 0), or a revision we merged already (a
        # peer that reconnected keeps counting; one restarted counts again from 1, and what it knew is
        # static knowledge we hold anyway).
        merged = self.merged_union if self.brain.leader is not None else self.merged
        return all(rev == 0 or rev in self.sets.get(a, ()) or rev <= merged.get(a, 0) for a, rev in need.items())

    def _move(self, k: int, st: wire.State) -> None:
        """Our state of tick k is in: our cells follow us (before our beacon, long before our command); in a
        new home cell our obstacle set is put again (its cache there is new)."""
        old = self.nb.home
        cells = self.nb.on_state(k, (st.px, st.py))
        if cells is not None:
            self._out.append(cells)
            if cells.home != old and self.brain.rev:
                self._out.append(self._obstacle_set(max(self.k, 0)))

    def _act(self, k: int, now: float) -> None:
        st = self.h.states[k]
        if self.mode == "lockstep" and not self._guess:
            late = self.nb.intruders(k, self.h.beacons.get(k, {}))
            gone = "our router link went: what was in flight to us (a beacon, a set) is lost" if self.link_lost else ""
            self._guess = gone or (self.nb.unexpected(late[0]) if late else "")  # (the link first: their cause)
        self.link_lost = False
        if self._guess and self.guessed_k < 0:
            self.guessed_k = k
            log.warning("agent %d: tick %d: %s: acting without them; lockstep is no longer deterministic",
                        self.id, k, self._guess)
        self._guess = ""
        p = np.array([st.px, st.py])
        peers, lost = self._peers(k)
        if self.mode == "lockstep":  # exactly the peers' sets at k-1, as their beacons at k announce
            if self._linked[0] != k:  # (the wait gave up before all beacons came)
                self._link(k, p)
            linked = self._linked[1]
        else:  # realtime: whatever is latest
            linked = {a: max(self.sets.get(a, {0: {}})) for a in self.brain.linked(p, [*peers, *lost])}
        if self.k < 0 and k > 0:  # joining a mission under way: catch up on everything peers have cached
            linked = self.peer_sets.newest()
            log.info("agent %d: joining at tick %d; cached obstacle sets from agents %s: %s", self.id, k,
                     sorted(linked), sorted({o for revs in self.sets.values() for v in revs.values() for o in v}))
        shared = self.peer_sets.unmerged(linked, self.merged)
        swarm = None if self.brain.leader is None else self.peer_sets.unmerged(  # (every peer's set: at k-1, as
            {a: b.rev for a, b in self.h.beacons.get(k, {}).items()} if self.mode == "lockstep"  # announced at k)
            else self.peer_sets.newest(), self.merged_union)
        scan = scan_sets(self.h.scans, self.k + 1 if self.k >= 0 else k, k)
        plan = self.brain.plan(k, p, scan, peers, shared, swarm, lost, st.theta)
        if plan.grew:
            self._out.append(self._obstacle_set(k))
        self.planning = k  # our host computes the law with its other agents' plans, then hands it to us
        self._out.append(plan)

    def _command(self, k: int, v_mps: float, omega_radps: float, now: float) -> None:
        self.last_cmd = wire.Cmd(self.id, k, v_mps, omega_radps)  # (v, ω) at our heading θ_k
        self._waited.clear()  # (tick k's)
        self._out.append(self.last_cmd)
        cells = self.nb.after_command(k)
        if cells is not None:
            self._out.append(cells)
        self.last_act, self.acted, self.k, self.wait_since = now, now, k, None
        if k % 20 == 0:
            self._prune(k)

    def waiting_for(self) -> str:
        """What the next tick still lacks (for the log while we wait)."""
        k = self.k + 1
        waited = self._expected(k, self.h.clocks.get(k)) if k in self.h.states else frozenset()
        return self.h.lacks(k, waited, {a: rev for a, rev in self._linked[1].items() if rev}, self.sets)

    def _obstacle_set(self, k: int) -> wire.ObstacleSet:
        return own_set(self.id, k, self.brain.rev, self.brain.obstacle_sets())

    def _prune(self, k: int) -> None:
        self.h.prune(k)
        self.nb.prune(k)
        p, stale_k = (self.h.states[k].px, self.h.states[k].py), k - round(self.policy.fresh_s / self.s.meta.dt_s)
        living = self.h.living(self.h.clocks.get(k)) if self.mode == "lockstep" else set()
        self.h.forget_stale(lambda b: self.nb.audible(p, b), living, stale_k)
        self.peer_sets.prune(self.brain.leader is not None)

    def _advance(self, now: float) -> None:
        """Act on every tick the data allows (none while our plan waits for its law)."""
        if self.planning >= 0:
            return
        if self.mode == "realtime":  # act on the newest state once the peers' beacons for it are in, or
            k = max(self.h.states, default=-1)  # at the deadline a fraction of a period after it arrived
            if k <= self.k:
                return
            if self.beacon_sent < k:
                self._move(k, self.h.states[k])
                self._out.append(self._beacon(self.h.states[k]))
                self.beacon_sent = k
            fresh = self.h.beacons.get(k, {})
            due = self.act_at is not None and now >= self.act_at
            if due or all(a in fresh for a in self._expected(k, None)):
                self.act_at = None
                self._act(k, now)
            return
        while self.h.states:
            newest = max(self.h.states)
            k = self.k + 1 if self.k >= 0 and (self.k + 1) in self.h.states else newest
            if k <= self.k or not self._ready_lockstep(k, now):
                return
            self._act(k, now)
            if self.planning >= 0:
                return
