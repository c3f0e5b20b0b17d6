"""One agent's identity on the wire, inside its process's session (agent/host.py holds the session).

An `HostedAgent` is what makes a hosted agent indistinguishable from a lone one: its own robot interface (its state
in, its command out: agent/robot_io.py), its own publishers (obstacle set under its home cell, report `agent-<id>`;
its beacons go out in its host's batches, agent/beacons.py), its own liveliness token, its own gate (admission state
and intrusion tally) and rejection count around its AgentNode. It does not subscribe: the host's shared
subscriptions hand it the samples meant for it (`take` a message decoded once for everyone, or `decode` a raw sample
for it alone), and it publishes what its node returns.
"""

from __future__ import annotations

import logging
import time
from typing import Any, cast

import zenoh
from zenoh import ext

from agent.messages import Output, Received
from agent.neighbours import Cells
from agent.node import AgentNode
from agent.robot_io import Decoded, RobotFactory, keys_robot
from reconswarm.net.node import Invalid, RouterReach, Stop, Token
from reconswarm.net.runtime.inbox import Rejections
from reconswarm.net.runtime.session import Member
from reconswarm.net.trust.admission import Intrusion, IntrusionKind
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import BeaconBatch
from reconswarm.net.wire.cells import Cell
from reconswarm.net.wire.decode import AGENT, decode
from reconswarm.net.wire.hostwire import StateBatch
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.net.wire.report import report_to_wire

log = logging.getLogger("reconswarm.agent")
# (the kinds `HostedAgent.take` sorts a sample by, as tuples: `isinstance` with `A | B` builds the union each call)
PASSED = (Token, RouterReach, Stop)  # taken as they are
OWN = (wire.State, wire.Scan)  # for one agent: the others drop it
PEER_MESSAGES = (wire.Beacon, wire.ObstacleSet)  # a peer's: never in our own name from another session


def decode_sample(keys: Keys, key: str, payload: bytes, kind: str) -> Decoded:
    """A sample as a node input, for any agent (who may take it is `HostedAgent.take`'s question); a malformed one
    becomes Invalid."""
    try:
        return cast(Decoded, decode(keys, AGENT, key, payload, kind))  # (AGENT's kinds: what a node receives)
    except WireError as exc:
        return Invalid(key, str(exc))


class HostedAgent(Member):
    """One agent's publishers, token, gate and counters in a session, around its node.

    own_source: the session's id when co-hosted agents share it (the host hands them each other's beacons and
    sets with it as their source); None for a lone agent. Anything on our own keys that the session receives
    comes from another session.
    """

    def __init__(self, node: AgentNode, keys: Keys, session: zenoh.Session, rej: Rejections, gate: Gate,
                 robot: RobotFactory | None = None, own_source: str | None = None,
                 odometry: Any = None) -> None:
        self.node, self.keys, self.z, self.rej, self.gate = node, keys, session, rej, gate
        self.id, self.own_source = node.id, own_source
        self.home: Cell | None = None  # the cell we publish from (none declared yet)
        self.pub_obs: ext.AdvancedPublisher
        l_m = float(node.s.head_offsets[node.s.agent_index(self.id)])
        # Our robot: its state in, our command out (agent/robot_io.py; `odometry`: the host's callback for what the
        # interface subscribes to itself, ROS 2 mode's odometry).
        self.robot = (robot or keys_robot)(session, keys, self.id, l_m, node.s.meta.dt_s, node.timing,
                                           odometry or (lambda _sample: None))
        self.pub_report = session.declare_publisher(keys.report(gate.process))
        self.cells(node.cells())
        self.token: Any = None  # declared by `announce`, once the host listens for us

    def announce(self) -> None:
        """Declare our liveliness token: it tells the world this agent is ready to receive."""
        self.token = self.z.liveliness().declare_token(self.keys.alive_agent(self.id))

    def close(self) -> None:
        self.robot.close()
        if self.token is not None:
            super().close()

    def cells(self, c: Cells) -> None:
        """Publish from c.home (the obstacle set's cache moves with it: the node puts its set again); whom we
        listen to is the host's (agent/host.py)."""
        if c.home == self.home:
            return
        if self.home is not None:
            self.pub_obs.undeclare()
        self.home = c.home
        k = self.keys
        self.pub_obs = ext.declare_advanced_publisher(self.z, k.obstacles(c.home, self.id),
                                                      cache=ext.CacheConfig(max_samples=1))

    def decode(self, key: str, payload: bytes, kind: str, source: str, _at_s: float = 0.0) -> Received | None:
        """A raw sample for this agent alone: the node input (None: not for us, or refused by admission, which
        counts and logs it); a malformed one becomes Invalid (and is counted)."""
        if self.robot.owns(key):
            return self.robot.decode(key, payload, source, self.gate, self.rej)
        if key.endswith("/obstacles") and not self.admit_bytes(len(payload), source, key):
            return None
        return self.take(decode_sample(self.keys, key, payload, kind), key, source)

    def admit_bytes(self, n_bytes: int, source: str, key: str) -> bool:
        """An obstacle set's size, before it is decoded (refused: counted by our gate)."""
        return self.gate.admit_set_bytes(n_bytes, source, key, time.monotonic())

    def take(self, m: Decoded, key: str, source: str) -> Received | None:
        """A decoded sample, as this agent takes it: ours to act on, counted as invalid, or refused."""
        if m is None or isinstance(m, BeaconBatch | StateBatch):  # (batches: the host's, agent/host.py)
            return None
        if isinstance(m, PASSED):
            return m
        if isinstance(m, Invalid):
            self.rej.reject(key, m.reason)
            return m
        if isinstance(m, OWN) and m.id != self.id:
            return None
        if isinstance(m, PEER_MESSAGES) and m.id == self.id:
            if source == self.own_source:
                return None  # our own, back through our session's shared subscription
            what = "a beacon" if isinstance(m, wire.Beacon) else "an obstacle set"
            bad = Invalid(key, f"{what} on our own key from another session")
            self.rej.reject(key, bad.reason)
            return bad
        return m if self.gate.admit(m, source, key, time.monotonic()) else None

    def refuse_cohosted(self, agent_id: int, key: str, source: str) -> None:
        """A beacon or set in the name of an agent hosted with us, from another session: forged (the genuine ones
        are handed over in the process, never through the router), refused and counted by our gate."""
        why = f"agent {agent_id} is hosted in our process, not in session {source}"
        self.gate.refuse(Intrusion(IntrusionKind.IMPERSONATION, source, key, why), time.monotonic())

    def publish(self, out: Output) -> tuple[str, bytes] | None:
        """Put what the node returned (not a beacon: agent/beacons.py); an obstacle set: its key and payload (for
        co-hosted agents)."""
        if isinstance(out, wire.Cmd):
            self.robot.command(out, self.node.period_s)
        elif isinstance(out, wire.ObstacleSet):
            payload = wire.obstacles_to_wire(out)
            self.pub_obs.put(payload)
            assert self.home is not None
            return self.keys.obstacles(self.home, self.id), payload
        elif isinstance(out, Cells):
            self.cells(out)
        return None

    def report(self, final: bool = False) -> None:
        """Our telemetry to the monitor: counters every `telemetry_s` (our heartbeat) and at once when we first
        acted on a guess; our intrusion tally when it changed (at most once a second unless final)."""
        node = self.node
        r = self.gate.report(time.monotonic(), final, (node.rejected, node.guessed_k), node.timing.telemetry_s)
        if r is not None:
            self.pub_report.put(report_to_wire(r))
