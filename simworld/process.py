"""`reconswarm simworld`: the world process, its node (simworld/world.WorldNode) on the runtime.

The process is the runtime's loop (reconswarm/net/runtime/runtime.py) around one node and `WorldAdapter`, the world's
declarations: the clock, the truth, its reports and token, every liveliness token, and the robot interface chosen
once for the process (simworld/robot_io.py: the project's keys, or ROS 2 topics); `route` turns each sample into
the node's input (a token, a command its gate admitted, or Invalid, counted); `act` puts what the node returns:
clock, truth, and each robot's state through the robot interface. Every rule (membership, the barrier, the
clocks, stalls) is the node's.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import zenoh
from zenoh import ext

from reconswarm.errors import BadInput
from reconswarm.net.node import Exit, Invalid
from reconswarm.net.ros2 import ros2
from reconswarm.net.runtime import trace
from reconswarm.net.runtime.inbox import Inbox, Item, Rejections, Tag
from reconswarm.net.runtime.runtime import Runtime
from reconswarm.net.runtime.session import Member, ZenohOptions, serving
from reconswarm.net.timing import TIMING
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.net.wire.report import report_to_wire
from reconswarm.net.wire.wire import ClockMode
from reconswarm.scenario.model import load
from simworld.robot_io import KeysIO, RobotIO
from simworld.ros2_io import Ros2IO, Ros2Robots, ros2_world
from simworld.world import WorldInput, WorldNode, WorldOutput

log = logging.getLogger("reconswarm.simworld")
WORLD = 0  # the one node the process hosts
POLL_S = 0.05  # the node is stepped at least this often (its timers; WorldNode.stalled counts on it)


@dataclass(frozen=True)
class SimworldConfig:
    """The world process's options (the scenario's own [world] section is `scenario.WorldConfig`)."""

    scenario: Path
    zenoh: ZenohOptions
    clock: ClockMode = ClockMode.LOCKSTEP
    speed: float = 1.0
    run_id: str | None = None
    start_timeout_s: float = TIMING.start_timeout_s
    ros2_domain_id: int | None = None  # ROS 2 mode: odom out, cmd_vel in (simworld/ros2_io.py) in this domain


class WorldAdapter(Member):
    """The world's subscriptions, publishers, gate and token around its node (the runtime's Adapter); its robots are
    reached through `io` (simworld/robot_io.py), given by `robot_io`."""

    def __init__(self, node: WorldNode, run: str, session: zenoh.Session, io: RobotIOFactory | None = None) -> None:
        self.keys = k = Keys(run)
        self.inbox = Inbox()
        self.rej = Rejections("simworld")
        block = zenoh.CongestionControl.BLOCK
        z, timing = session, node.timing
        # Admission: commands (in ROS 2 mode cmd_vel) only from each agent's own session, bounded, for ticks we
        # published (the newest clock put, `act`), one per agent and tick.
        self.gate = Gate(node.s, "simworld")
        self.io = (io or _keys_io)(z, k, node, self.gate, self.inbox)
        self.pub_clock = z.declare_publisher(k.clock, congestion_control=block)
        # The record's input: kept and numbered, so the monitor recovers a truth that was lost (advanced pub/sub).
        self.pub_truth = ext.declare_advanced_publisher(
            z, k.truth, congestion_control=block, cache=ext.CacheConfig(max_samples=timing.truth_cache_ticks),
            sample_miss_detection=ext.MissDetectionConfig(heartbeat=None,
                                                          sporadic_heartbeat=timing.truth_heartbeat_s))
        self.pub_report = z.declare_publisher(k.report("simworld"))
        self.subs = [z.liveliness().declare_subscriber(k.alive_all, self.inbox.handler(), history=True)]
        self.token = z.liveliness().declare_token(k.alive_simworld)

    def close(self) -> None:
        self.io.close()
        super().close()

    # ------------------------------------------------------------------------------------------ in

    def route(self, items: Sequence[tuple[Tag, Item]], now_s: float) -> dict[int, list[WorldInput]]:
        """The node's inputs from a batch of samples, in order of arrival."""
        got: list[WorldInput] = [self._invalid(key, reason) for key, reason in self.io.dropped()]
        for _tag, item in items:
            m = self.decode(*item)
            if isinstance(m, list):
                got += m
            elif m is not None:
                got.append(m)
        return {WORLD: got}

    def decode(self, key: str, payload: bytes, kind: str, source: str,
               at_s: float) -> WorldInput | list[WorldInput] | None:
        """A sample as the node's input (None: not the world's, or refused by the gate, which counts and logs it; a
        host's command batch: the commands admitted); a malformed one is Invalid (counted)."""
        try:
            return self.io.decode(key, payload, kind, source, at_s)
        except (ros2.Ros2Error, WireError) as exc:
            return self._invalid(key, str(exc))

    def _invalid(self, key: str, reason: str) -> Invalid:
        self.rej.reject(key, reason)
        return Invalid(key, reason)

    # ----------------------------------------------------------------------------------------- out

    def act(self, who: Any, out: WorldOutput, now_s: float) -> bool:
        """Put what the node returned under its key (in ROS 2 mode a state as odometry, its scan on its own key); a
        tick's states go out together, before its truth."""
        if isinstance(out, wire.Clock):
            trace.mark(trace.Mark.CLOCK_PUT, out.k, 0)
            self.pub_clock.put(wire.clock_to_wire(out))
            self.gate.world_k, self.gate.t = out.k, out.t  # (the newest tick published; the intrusions' first_t)
        elif isinstance(out, wire.Truth):
            self.io.flush()
            self.pub_truth.put(wire.truth_to_wire(out))
        elif isinstance(out, wire.State):
            self.io.put_state(out)
        return False

    def idle(self, who: Any, now_s: float) -> None:
        self.io.flush()
        self.report()

    def exited(self, who: Any, code: Exit, now_s: float) -> None:
        self.io.flush()
        self.report(final=True)

    def report(self, final: bool = False) -> None:
        r = self.gate.report(time.monotonic(), final)
        if r is not None:
            self.pub_report.put(report_to_wire(r))


class RobotIOFactory(Protocol):
    """Makes the world's robot interface on its session (the adapter's inbox takes what it subscribes to)."""

    def __call__(self, session: zenoh.Session, keys: Keys, node: WorldNode, gate: Gate, inbox: Inbox) -> RobotIO: ...


def _keys_io(session: zenoh.Session, keys: Keys, node: WorldNode, gate: Gate, inbox: Inbox) -> RobotIO:
    return KeysIO(session, keys, node.ids, gate, inbox.handler(rows=True))  # (a host's commands: its rows)


def robot_io(ros2_domain_id: int | None) -> RobotIOFactory:
    """The robot interface of this process: the project's keys, or ROS 2 topics in that domain (the node's plant
    then a `Ros2Robots`)."""
    if ros2_domain_id is None:
        return _keys_io

    def make(session: zenoh.Session, keys: Keys, node: WorldNode, gate: Gate, inbox: Inbox) -> RobotIO:
        if not isinstance(node.robots, Ros2Robots):
            raise TypeError("ROS 2 mode: the world's plant is a robot base (Ros2Robots)")
        return Ros2IO(session, keys, gate, ros2_domain_id, node.robots, inbox.callback(),
                      node.s.meta.dt_s / node.speed, node.timing)

    return make


def run(cfg: SimworldConfig) -> int:
    clock = ClockMode(cfg.clock)
    if not cfg.speed > 0:
        raise BadInput(f"--speed: must be > 0, got {cfg.speed}")
    s = load(cfg.scenario)
    timing = replace(TIMING, start_timeout_s=cfg.start_timeout_s)
    if cfg.ros2_domain_id is not None and clock != ClockMode.REALTIME:
        raise BadInput("--ros2: runs on the realtime clock only (ROS 2 topics carry no tick), not --clock lockstep")
    node = WorldNode(s, clock, cfg.speed, timing) if cfg.ros2_domain_id is None else ros2_world(s, cfg.speed, timing)
    with serving(cfg.zenoh, "simworld") as (session, stop):
        adapter = WorldAdapter(node, cfg.run_id or s.meta.name, session, robot_io(cfg.ros2_domain_id))
        log.info("simworld up (run %s, %s clock): waiting for %d agents and the monitor", adapter.keys.run,
                 clock, len(node.ids))
        wall0 = time.monotonic()
        exits = Runtime(session, "simworld", stop, adapter.inbox, POLL_S).run({WORLD: node}, adapter,
                                                                            started=lambda: node.started)
        if not node.started:
            return 0
        log.info("mission ended (%s) after %.2f s wall; stats %s", exits[WORLD].reason, time.monotonic() - wall0,
                 node.stats())
        time.sleep(TIMING.world_end_linger_s)  # let the last messages reach the monitor before the session closes
        adapter.close()
        return 0
