"""`reconswarm agent --id I`: one agent as its own process, the AgentNode (agent/node.py) behind zenoh.

This adapter only moves bytes: it subscribes to its state (which carries its scan; in ROS 2 mode its odometry
and its scan's own key), the clock, liveliness, and the beacons
and obstacle sets (advanced subscribers: a late or restarted agent, or one entering a cell, receives each
publisher's current set) of the cells the node names (agent/neighbours.py: re-declared as the agent
moves, every cell for the virtual leader); it publishes its beacon and set under its own cell. It decodes
what arrives into wire dataclasses (dropping and counting what is malformed),
hands each batch to the node with the wall time, and publishes what the node returns: its beacon,
obstacle set (advanced publisher, cached) and command, and its report (telemetry and heartbeat for the
monitor); it declares the agent's liveliness token.
When the node asks for a new session, the session is replaced and the node, with everything it knows,
is kept.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import zenoh
from zenoh import ext

from agent.messages import Exit, Input, Invalid, Joined, Left, Output, Reconnect, WorldToken
from agent.neighbours import Cells
from agent.node import AgentNode
from agent.ros2_io import AgentRos2
from reconswarm.errors import BadInput
from reconswarm.net import wire
from reconswarm.net.cells import Cell
from reconswarm.net.gate import Gate
from reconswarm.net.report import report_to_wire
from reconswarm.net.session import Inbox, Member, Rejections, StartMark, Stopper, ZenohOptions, serving
from reconswarm.net.timing import TIMING, Timing
from reconswarm.scenario import load

log = logging.getLogger("reconswarm.agent")
RECONNECT = -1  # AgentLink.run's answer when the session must be opened again


@dataclass(frozen=True)
class AgentConfig:
    agent_id: int
    scenario: Path
    zenoh: ZenohOptions
    run_id: str | None = None
    timing: Timing = TIMING
    ros2_domain_id: int | None = None  # ROS 2 mode: odom in, cmd_vel out (agent/ros2_io.py) in this domain


class AgentLink(Member):
    """One zenoh session of an agent: its publishers, subscribers and token, around the node."""

    def close(self) -> None:
        if self.ros2 is not None:
            self.ros2.close()
        super().close()

    def __init__(self, node: AgentNode, keys: wire.Keys, session: zenoh.Session, rej: Rejections, gate: Gate,
                 ros2_domain_id: int | None = None) -> None:
        self.node, self.keys, self.z, self.rej, self.gate = node, keys, session, rej, gate
        self.id = node.id
        self.inbox = Inbox()
        block = zenoh.CongestionControl.BLOCK
        k = self.keys
        z = session
        self.home: Cell | None = None  # the cell we publish from (none declared yet)
        self.pub_beacon: zenoh.Publisher
        self.pub_obs: ext.AdvancedPublisher
        self.listening: dict[Cell | None, tuple[zenoh.Subscriber, ext.AdvancedSubscriber]] = {}
        l_m = float(node.s.head_offsets[node.s.agent_index(self.id)])
        self.ros2 = None if ros2_domain_id is None else AgentRos2(
            z, ros2_domain_id, self.id, l_m, node.s.meta.dt_s, self.inbox.urgent)
        self.pub_cmd = None if self.ros2 else z.declare_publisher(k.cmd(self.id), congestion_control=block)
        self.pub_report = z.declare_publisher(k.report(gate.process))
        self.cb = cb = self.inbox.handler()
        self.cells(node.nb.current())
        self.subs = [
            # Our state starts a tick: it wakes the loop at once; the rest wakes it only once the node's
            # count of what it still needs is in (one wake-up per tick, not one per message).
            *([z.declare_subscriber(k.scan(self.id), cb)] if self.ros2 else
              [z.declare_subscriber(k.state(self.id), self.inbox.handler(urgent=True))]),
            z.declare_subscriber(k.clock, cb),
            z.liveliness().declare_subscriber(k.alive_all, cb, history=True),
        ]
        # Declared last: the token tells the world this agent is ready to receive.
        self.token = z.liveliness().declare_token(k.alive_agent(self.id))

    def cells(self, c: Cells) -> None:
        """Publish from c.home (the obstacle set's cache moves with it: the node puts its set again), listen
        to c.listen: new cells are declared before the old ones go."""
        z, k, block = self.z, self.keys, zenoh.CongestionControl.BLOCK
        if c.home != self.home:
            if self.home is not None:
                self.pub_beacon.undeclare()
                self.pub_obs.undeclare()
            self.home = c.home
            self.pub_beacon = z.declare_publisher(k.beacon(c.home, self.id), congestion_control=block)
            self.pub_obs = ext.declare_advanced_publisher(z, k.obstacles(c.home, self.id),
                                                          cache=ext.CacheConfig(max_samples=1))
        want: set[Cell | None] = {None} if c.listen is None else set(c.listen)
        remote = zenoh.Locality.REMOTE
        for cell in want - self.listening.keys():
            # Our own announcements are not delivered back (REMOTE); anyone else's on our keys are checked.
            self.listening[cell] = (
                z.declare_subscriber(k.cell_agents(cell, "beacon"), self.cb, allowed_origin=remote),
                ext.declare_advanced_subscriber(z, k.cell_agents(cell, "obstacles"), self.cb, allowed_origin=remote,
                                                history=ext.HistoryConfig(detect_late_publishers=True)))
        for cell in self.listening.keys() - want:
            for sub in self.listening.pop(cell):
                sub.undeclare()

    def decode(self, key: str, payload: bytes, kind: str, source: str, _at_s: float) -> Input | None:
        """The sample as a node input (None: not for us, or refused by admission, which counts and logs it);
        a malformed one becomes Invalid (and is logged)."""
        if self.ros2 is not None and self.ros2.owns(key):
            odom = self.ros2.decode(key, payload)
            if isinstance(odom, Invalid):
                self.rej.reject(key, odom.reason)
            return odom
        if key.endswith("/obstacles") and not self.gate.admit_set_bytes(len(payload), source, key, time.monotonic()):
            return None
        m = self._decode(key, payload, kind)
        if isinstance(m, Invalid | Joined | Left | WorldToken) or m is None:
            return m
        return m if self.gate.admit(m, source, key, time.monotonic()) else None

    def _decode(self, key: str, payload: bytes, kind: str) -> Input | None:
        try:
            what, aid, leaf = self.keys.parse(key)
            if what == "alive":
                if leaf == "agent" and aid is not None:
                    return Left(aid) if kind == "DELETE" else Joined(aid)
                return WorldToken(kind != "DELETE") if leaf == "simworld" else None
            if what == "clock":
                return wire.clock_from_wire(payload)
            if what != "agent" or aid is None:
                return None
            if leaf == "state" and aid == self.id:
                return wire.state_from_wire(payload, aid)
            if leaf == "scan" and aid == self.id:
                return wire.scan_from_wire(payload, aid)
            if leaf == "beacon":
                b = wire.beacon_from_wire(payload, aid)
                if aid == self.id:
                    raise wire.WireError("a beacon on our own key from another session")
                return b
            if leaf == "obstacles":
                o = wire.obstacles_from_wire(payload, aid)
                if aid == self.id:
                    raise wire.WireError("an obstacle set on our own key from another session")
                return o
            return None
        except wire.WireError as exc:
            self.rej.reject(key, str(exc))
            return Invalid(key, str(exc))

    def publish(self, out: Output) -> None:
        if isinstance(out, wire.Cmd):
            if self.ros2 is not None:
                self.ros2.command(out)
            elif self.pub_cmd is not None:
                self.pub_cmd.put(wire.cmd_to_wire(out))
        elif isinstance(out, wire.Beacon):
            self.pub_beacon.put(wire.beacon_to_wire(out))
        elif isinstance(out, wire.ObstacleSet):
            self.pub_obs.put(wire.obstacles_to_wire(out))
        elif isinstance(out, Cells):
            self.cells(out)

    def run(self, stop: Stopper) -> int:
        """Feed the node until it exits or asks for a new session (RECONNECT), or a signal stops us."""
        node, poll_s = self.node, self.node.timing.agent_poll_s
        mark = StartMark()
        while not stop.stopped:
            mark(node.started)
            wake = node.wake_at_s()
            items = self.inbox.take(node.awaiting(time.monotonic()),
                                    poll_s if wake is None else min(poll_s, max(0.0, wake - time.monotonic())))
            batch = [m for m in (self.decode(*it) for it in items) if m is not None]
            if self.ros2 is not None:
                batch += self.ros2.take_invalid()
            for out in node.step(batch, time.monotonic()):
                if isinstance(out, Exit):
                    self.report(final=True)
                    return out.code
                if isinstance(out, Reconnect):
                    return RECONNECT
                self.publish(out)
            self.report()
        self.report(final=True)
        return 0

    def report(self, final: bool = False) -> None:
        """Our telemetry to the monitor: counters every `telemetry_s` (our heartbeat) and at once when we first
        acted on a guess; our intrusion tally when it changed (at most once a second unless final)."""
        node = self.node
        r = self.gate.report(time.monotonic(), final, (node.rejected, node.guessed_k), node.timing.telemetry_s)
        if r is not None:
            self.pub_report.put(report_to_wire(r))


def run(cfg: AgentConfig) -> int:
    s = load(cfg.scenario)
    if cfg.agent_id not in {a.id for a in s.agents}:
        raise BadInput(f"--id: agent {cfg.agent_id} is not in {cfg.scenario}")
    node = AgentNode(s, cfg.agent_id, time.monotonic(), cfg.timing)  # kept across new sessions
    keys = wire.Keys(cfg.run_id or s.meta.name)
    rej = Rejections(f"agent {cfg.agent_id}")
    gate = Gate(s, f"agent-{cfg.agent_id}")  # kept across new sessions, like the node
    while True:
        with serving(cfg.zenoh, f"agent {cfg.agent_id}", cfg.timing.session_open_timeout_s) as (session, stop):
            link = AgentLink(node, keys, session, rej, gate, cfg.ros2_domain_id)
            log.info("agent %d up (run %s)", cfg.agent_id, keys.run)
            code = link.run(stop)
            if node.ended and not stop.stopped:
                time.sleep(cfg.timing.agent_end_linger_s)  # let the monitor see the end before our token goes
            link.close()
            if code != RECONNECT:
                log.info("agent %d done: last tick %d, %d messages rejected, %d intrusions refused", cfg.agent_id,
                         node.k, node.rejected, gate.count)
                return code
            # We stopped acting although the mission goes on (seen after a router restart: a route to one of
            # our keys was not restored): a new session re-declares everything; the node keeps all it knows
            # (peers' last positions, lost peers, knowledge, revisions, escape state).
            log.warning("agent %d: no command for %.0f s%s: opening a new session", cfg.agent_id,
                        time.monotonic() - node.last_act, " (the world's token gone)" if node.world_gone else "")
            node.reconnected(time.monotonic())
