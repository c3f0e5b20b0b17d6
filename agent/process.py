"""`reconswarm agent --id I`: one agent as its own process, the AgentBrain behind a zenoh adapter.

Subscribes to its state and scan, the clock, every agent's beacon and obstacle set (an advanced
subscriber: a late or restarted agent receives each publisher's current set), and liveliness.
Publishes its beacon, obstacle set (advanced publisher, cached) and command; declares its token.

Lockstep (the clock says so): at tick k the agent waits for its state (and scan), announces its beacon
(with the revision of its obstacle set at k-1), waits for the beacons of every live agent and the
obstacle sets of those within link range (all of them for the virtual leader), then plans and
commands. Realtime: it acts shortly after each new state on whatever it has (latest beacons, sets).
A peer whose beacon is missing is kept where it was last seen (a static obstacle).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zenoh

from agent.brain import AgentBrain, Peer
from reconswarm.errors import BadInput
from reconswarm.net import wire
from reconswarm.net.session import Inbox, Member, Rejections, Stopper, ZenohOptions, serving
from reconswarm.scenario import Scenario, load

log = logging.getLogger("reconswarm.agent")
WORLD_SILENCE_S = 30.0  # exit 3 if the world says nothing for this long after the mission began
RESUBSCRIBE_S = 5.0  # no command for this long, though the world re-sends a waiting tick every 0.5 s: new session
PEER_SILENT_S = 2.0  # a peer whose beacons stopped this long ago is not waited for
RECONNECT = -1  # AgentNode.run's answer when the session must be opened again


@dataclass(frozen=True)
class AgentConfig:
    agent_id: int
    scenario: Path
    zenoh: ZenohOptions
    run_id: str | None = None
    wait_timeout_s: float = 1.0  # lockstep: longest wait for a peer's beacon or obstacle set


class AgentNode(Member):
    def __init__(self, cfg: AgentConfig, s: Scenario, session: zenoh.Session,
                 brain: AgentBrain | None = None) -> None:
        from zenoh import ext

        self.cfg, self.s, self.z = cfg, s, session
        self.id = cfg.agent_id
        self.keys = wire.Keys(cfg.run_id or s.meta.name)
        self.brain = brain if brain is not None else AgentBrain(s, self.id)  # (kept across a new session)
        self.resumed = brain is not None
        self.radius = float(self.brain.r[0])
        self.rej = Rejections(f"agent {self.id}")
        self.inbox = Inbox()
        self.states: dict[int, wire.State] = {}
        self.scans: dict[int, wire.Scan] = {}
        self.clocks: dict[int, wire.Clock] = {}
        self.beacons: dict[int, dict[int, wire.Beacon]] = {}
        self.last_seen: dict[int, wire.Beacon] = {}
        self.sets: dict[int, dict[int, dict[str, np.ndarray]]] = {}  # peer -> rev -> obstacle sets
        # Revisions already merged (into the brain's own set / the leader's union): merging a set again
        # cannot change a hull, so it is skipped.
        self.merged: dict[int, int] = {}
        self.merged_union: dict[int, int] = {}
        self.alive: set[int] = set()
        self.k = -1  # last tick commanded
        self.beacon_sent = -1
        self.wait_since: float | None = None
        self.mode = "lockstep"
        self.period_s = 0.0
        self.act_at: float | None = None
        self.last_clock = time.monotonic()
        self.ended = False
        self.last_cmd: bytes | None = None
        self.heard: dict[int, float] = {}  # wall time of each peer's latest beacon (or of its token)
        self.last_act = time.monotonic()  # wall time of our latest command
        self.state_at: dict[int, float] = {}  # wall time each tick's state arrived (while waiting for the rest)
        self._linked: tuple[int, dict[int, int]] = (-1, {})  # (tick, linked peer -> its set's revision)
        self.beacon_again = 0.0
        self.told_waiting = 0.0
        block = zenoh.CongestionControl.BLOCK
        k = self.keys
        z = session
        self.pub_beacon = z.declare_publisher(k.beacon(self.id), congestion_control=block)
        self.pub_cmd = z.declare_publisher(k.cmd(self.id), congestion_control=block)
        self.pub_obs = ext.declare_advanced_publisher(z, k.obstacles(self.id), cache=ext.CacheConfig(max_samples=1))
        cb = self.inbox.callback
        remote = zenoh.Locality.REMOTE
        self.subs = [
            z.declare_subscriber(k.state(self.id), cb),
            z.declare_subscriber(k.scan(self.id), cb),
            z.declare_subscriber(k.clock, cb),
            # Our own announcements are not delivered back (REMOTE); anyone else's on our keys are checked.
            z.declare_subscriber(k.all_agents("beacon"), cb, allowed_origin=remote),
            ext.declare_advanced_subscriber(z, k.all_agents("obstacles"), cb, allowed_origin=remote,
                                            history=ext.HistoryConfig(detect_late_publishers=True)),
            z.liveliness().declare_subscriber(k.alive_all, cb, history=True),
        ]
        # Declared last: the token tells the world this agent is ready to receive.
        self.token = z.liveliness().declare_token(k.alive_agent(self.id))

    # ------------------------------------------------------------------------------------------ input

    def handle(self, key: str, payload: bytes, kind: str) -> None:
        try:
            what, aid, leaf = self.keys.parse(key)
            if what == "alive":
                if leaf == "agent" and aid is not None:
                    if kind == "DELETE":
                        self.alive.discard(aid)
                    else:
                        self.alive.add(aid)
                        self.heard.setdefault(aid, time.monotonic())
                return
            if what == "clock":
                c = wire.clock_from_wire(payload)
                self.clocks[c.k] = c
                self.last_clock = time.monotonic()
                self.mode = c.mode
                self.period_s = self.s.meta.dt_s / c.speed if c.speed > 0 else 0.0
                if c.end:
                    self.ended = True
                return
            if what != "agent" or aid is None:
                return
            if leaf == "state" and aid == self.id:
                st = wire.state_from_wire(payload, aid)
                if st.k == self.k and self.last_cmd is not None:  # the world missed our command: again
                    self.pub_cmd.put(self.last_cmd)
                    return
                self.states[st.k] = st
                if self.mode == "realtime":
                    self.act_at = time.monotonic() + 0.25 * self.period_s
            elif leaf == "scan" and aid == self.id:
                sc = wire.scan_from_wire(payload, aid)
                self.scans[sc.k] = sc
            elif leaf == "beacon":
                b = wire.beacon_from_wire(payload, aid)
                if aid == self.id:
                    raise wire.WireError("a beacon on our own key from another session")
                self.beacons.setdefault(b.k, {})[aid] = b
                self.heard[aid] = time.monotonic()
                if aid not in self.last_seen or b.k >= self.last_seen[aid].k:
                    self.last_seen[aid] = b
            elif leaf == "obstacles":
                o = wire.obstacles_from_wire(payload, aid)
                if aid == self.id:
                    raise wire.WireError("an obstacle set on our own key from another session")
                self.sets.setdefault(aid, {})[o.rev] = {oid: np.array(v, dtype=np.float64)
                                                         for oid, v in o.obstacles.items()}
        except wire.WireError as exc:
            self.rej.reject(key, str(exc))

    # --------------------------------------------------------------------------------------- planning

    def _scan_sets(self, k_from: int, k_to: int) -> dict[str, np.ndarray]:
        pts: dict[str, list[tuple[float, float]]] = {}
        for kk in range(k_from, k_to + 1):
            sc = self.scans.pop(kk, None)
            if sc is not None:
                for x, y, oid in sc.points:
                    pts.setdefault(oid, []).append((x, y))
        return {oid: np.array(v, dtype=np.float64) for oid, v in pts.items()}

    def _peers(self, k: int) -> list[wire.Beacon]:
        fresh = self.beacons.get(k, {})
        return [fresh.get(a, b) for a, b in self.last_seen.items()]

    def _ready_lockstep(self, k: int) -> bool:
        """True once everything tick k needs is in (or the wait timed out)."""
        st, clock = self.states.get(k), self.clocks.get(k)
        if st is None:
            return False
        if clock is None or (st.scan_n > 0 and k not in self.scans):
            # The tick's clock or scan may have been lost (an outage): after a while, go on without it
            # (the newest clock's list of agents; the next scan sees the same contour again).
            first = self.state_at.setdefault(k, time.monotonic())
            if time.monotonic() - first < self.cfg.wait_timeout_s or not self.clocks:
                return False
            clock = self.clocks[max(self.clocks)]
        if self.beacon_sent < k or time.monotonic() > self.beacon_again:  # (again if peers may have lost it)
            self.pub_beacon.put(wire.beacon_to_wire(wire.Beacon(
                self.id, k, st.t, st.px, st.py, self.radius, self.brain.rev, self.rej.count)))
            if self.beacon_sent < k:
                self.wait_since = time.monotonic()
            elif self.brain.rev:  # stuck on this tick: peers may have lost our obstacle set too
                self.pub_obs.put(self._obstacles_wire(k))
            self.beacon_sent = k
            self.beacon_again = time.monotonic() + 0.5
        if self.wait_since is not None and time.monotonic() - self.wait_since > self.cfg.wait_timeout_s:
            log.warning("agent %d: tick %d: gave up waiting for peers' data", self.id, k)
            return True
        fresh = self.beacons.get(k, {})
        now = time.monotonic()
        # A peer silent for PEER_SILENT_S (alive by its token, but saying nothing) is not waited for.
        if any(a not in fresh and now - self.heard.get(a, now) < PEER_SILENT_S
               for a in clock.alive if a != self.id and a in self.alive):
            return False
        if self._linked[0] != k:
            fresh_peers = [Peer(a, b.px, b.py, b.radius) for a, b in fresh.items()]
            self._linked = (k, {a: fresh[a].rev for a in self.brain.linked(np.array([st.px, st.py]), fresh_peers)})
        need = {a: b.rev for a, b in fresh.items()} if self.brain.leader is not None else self._linked[1]
        # A set is there, or nothing to wait for: an empty set (rev 0), or a revision we merged already (a
        # peer that reconnected keeps counting; one restarted counts again from 1, and what it knew is
        # static knowledge we hold anyway).
        merged = self.merged_union if self.brain.leader is not None else self.merged
        return all(rev == 0 or rev in self.sets.get(a, ()) or rev <= merged.get(a, 0) for a, rev in need.items())

    def _unmerged(self, wanted: dict[int, int], merged: dict[int, int]) -> list[dict[str, np.ndarray]]:
        """The sets at the wanted revisions that are not merged yet (and mark them merged)."""
        out = []
        for a in sorted(wanted):
            rev = wanted[a]
            if rev == 0 or merged.get(a, 0) >= rev:
                continue
            out.append(self._latest_set(a, rev))
            merged[a] = rev
        return out

    def _latest_set(self, peer: int, rev: int | None) -> dict[str, np.ndarray]:
        revs = self.sets.get(peer, {})
        if rev is not None and rev in revs:
            return revs[rev]
        usable = [r for r in revs if rev is None or r <= rev]
        return revs[max(usable)] if usable else {}

    def act(self, k: int) -> None:
        st = self.states[k]
        p = np.array([st.px, st.py])
        peers = [Peer(b.id, b.px, b.py, b.radius) for b in self._peers(k)]
        if self.mode == "lockstep":  # exactly the peers' sets at k-1, as their beacons at k announce
            fresh = self.beacons.get(k, {})
            if self._linked[0] != k:  # (the wait gave up before all beacons came)
                fresh_peers = [Peer(a, b.px, b.py, b.radius) for a, b in fresh.items()]
                self._linked = (k, {a: fresh[a].rev for a in self.brain.linked(p, fresh_peers)})
            linked = self._linked[1]
            every = {a: b.rev for a, b in fresh.items()}
        else:  # realtime: whatever is latest
            linked = {a: max(self.sets.get(a, {0: None})) for a in self.brain.linked(p, peers)}
            every = {a: max(revs) for a, revs in self.sets.items() if revs}
        if self.k < 0 and k > 0:  # joining a mission under way: catch up on everything peers have cached
            linked = {a: max(revs) for a, revs in self.sets.items() if revs}
            log.info("agent %d: joining at tick %d; cached obstacle sets from agents %s: %s", self.id, k,
                     sorted(linked), sorted({o for revs in self.sets.values() for v in revs.values() for o in v}))
        shared = self._unmerged(linked, self.merged)
        swarm = self._unmerged(every, self.merged_union) if self.brain.leader is not None else None
        scan = self._scan_sets(self.k + 1 if self.k >= 0 else k, k)
        u, grew = self.brain.tick(k, p, scan, peers, shared, swarm)
        if grew:
            self.pub_obs.put(self._obstacles_wire(k))
        self.last_cmd = wire.cmd_to_wire(wire.Cmd(self.id, k, float(u[0]), float(u[1])))
        self.pub_cmd.put(self.last_cmd)
        self.last_act = time.monotonic()
        self.k = k
        self.wait_since = None
        if k % 20 == 0:
            self._prune(k)

    def _waiting_for(self) -> str:
        """What the next tick still lacks (for the log while we wait)."""
        k = self.k + 1
        if k not in self.states:
            newest = max(self.states, default=None), max(self.clocks, default=None)
            return f"tick {k}: no state yet (newest state {newest[0]}, newest clock {newest[1]})"
        clock = self.clocks.get(k)
        missing = [] if clock is not None else ["clock"]
        if self.states[k].scan_n > 0 and k not in self.scans:
            missing.append("scan")
        fresh = self.beacons.get(k, {})
        peers = sorted(a for a in (clock.alive if clock else ()) if a != self.id and a in self.alive and a not in fresh)
        if peers:
            missing.append(f"beacons of {peers}")
        sets = sorted(a for a, rev in self._linked[1].items() if rev and rev not in self.sets.get(a, ()))
        if sets:
            missing.append(f"obstacle sets of {sets}")
        return f"tick {k}: waiting for {', '.join(missing) or 'nothing'}"

    def _obstacles_wire(self, k: int) -> bytes:
        sets = {oid: tuple(map(tuple, h.tolist())) for oid, h in self.brain.obstacle_sets().items()}
        return wire.obstacles_to_wire(wire.ObstacleSet(self.id, k, self.brain.rev, sets))

    def _prune(self, k: int) -> None:
        for store in (self.states, self.clocks, self.beacons, self.scans, self.state_at):
            for kk in [x for x in store if x < k - 2]:
                del store[kk]
        for a, revs in self.sets.items():  # keep the newest merged revision and everything after it
            done = min(self.merged.get(a, 0), self.merged_union.get(a, 0) if self.brain.leader else 2**62)
            for r in [r for r in revs if r < done]:
                del revs[r]

    def step(self) -> None:
        """Advance as far as the data allows."""
        if self.mode == "realtime":  # act on the newest state once the peers' beacons for it are in, or
            if not self.states:      # at the deadline a quarter of a period after it arrived
                return
            k = max(self.states)
            if k <= self.k:
                return
            if self.beacon_sent < k:
                st = self.states[k]
                self.pub_beacon.put(wire.beacon_to_wire(wire.Beacon(
                    self.id, k, st.t, st.px, st.py, self.radius, self.brain.rev, self.rej.count)))
                self.beacon_sent = k
            fresh = self.beacons.get(k, {})
            due = self.act_at is not None and time.monotonic() >= self.act_at
            if due or all(a in fresh for a in self.alive if a != self.id):
                self.act_at = None
                self.act(k)
            return
        while True:
            if not self.states:
                return
            newest = max(self.states)
            k = self.k + 1 if self.k >= 0 and (self.k + 1) in self.states else newest
            if k <= self.k or not self._ready_lockstep(k):
                return
            self.act(k)

    def run(self, stop: Stopper) -> int:
        started = self.resumed  # a new session of an agent already in the mission watches at once
        while not stop.stopped and not self.ended:
            item = self.inbox.get(timeout=0.05 if self.act_at is None else max(0.0, self.act_at - time.monotonic()))
            if item is not None:
                self.handle(*item)
                for more in self.inbox.drain():
                    self.handle(*more)
            self.step()
            if not started and self.clocks:  # the mission began: the watch starts now
                started, self.last_act = True, time.monotonic()
            if started and time.monotonic() - self.last_clock > WORLD_SILENCE_S:
                log.error("agent %d: no clock from the world for %.0f s", self.id, WORLD_SILENCE_S)
                return 3
            if started and time.monotonic() - self.last_act > RESUBSCRIBE_S:
                return RECONNECT
            if started and time.monotonic() - self.last_act > 1.0 and time.monotonic() > self.told_waiting + 1.0:
                self.told_waiting = time.monotonic()
                log.info("agent %d: %s", self.id, self._waiting_for())
        return 0

def run(cfg: AgentConfig) -> int:
    s = load(cfg.scenario)
    if cfg.agent_id not in {a.id for a in s.agents}:
        raise BadInput(f"--id: agent {cfg.agent_id} is not in {cfg.scenario}")
    brain: AgentBrain | None = None
    while True:
        with serving(cfg.zenoh, f"agent {cfg.agent_id}") as (session, stop):
            node = AgentNode(cfg, s, session, brain)
            log.info("agent %d up (run %s)", cfg.agent_id, node.keys.run)
            code = node.run(stop)
            if node.ended and not stop.stopped:
                time.sleep(0.5)  # let the monitor see the end of the mission before our token goes
            node.close()
            if code != RECONNECT:
                log.info("agent %d done: last tick %d, %d messages rejected", cfg.agent_id, node.k, node.rej.count)
                return code
            # We stopped acting although the mission goes on (seen after a router restart: a route to one of
            # our keys was not restored): a new session re-declares everything, with the same knowledge.
            log.warning("agent %d: no command for %.0f s: opening a new session", cfg.agent_id, RESUBSCRIBE_S)
            brain = node.brain
