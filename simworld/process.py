"""`reconswarm simworld`: the world process, a thin zenoh adapter around `simworld.world.WorldNode`.

It decodes commands and liveliness changes into the node, calls `WorldNode.step` with the time, and
puts what the step returns on the wire: clock, truth, and each agent's state with its scan in one message (in
ROS 2 mode the state as odometry and the scan on its own key). The tick logic (readiness
barrier, lockstep and realtime clocks, re-publish, hold-then-stop, strikes) is in world.py.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path

import zenoh
from zenoh import ext

from reconswarm.errors import BadInput
from reconswarm.net import ros2, wire
from reconswarm.net.gate import Gate
from reconswarm.net.inbox import Inbox, Rejections
from reconswarm.net.keys import Keys, WireError
from reconswarm.net.lifecycle import StartMark, Stopper
from reconswarm.net.membership import Membership
from reconswarm.net.report import report_to_wire
from reconswarm.net.session import Member, ZenohOptions, serving
from reconswarm.net.timing import TIMING
from reconswarm.net.uplink import LinkChange, Uplink
from reconswarm.net.wire import ClockMode
from reconswarm.scenario.model import load
from simworld.ros2_io import Ros2World, WorldRos2
from simworld.world import Phase, TickOut, WorldNode

log = logging.getLogger("reconswarm.simworld")


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
    """Moves bytes between zenoh and the node: decode in, encode out."""

    def close(self) -> None:
        if self.ros2 is not None:
            self.ros2.close()
        super().close()

    def __init__(self, node: WorldNode, run: str, session: zenoh.Session, ros2_domain_id: int | None = None) -> None:
        self.node = node
        self.keys = k = Keys(run)
        self.inbox = Inbox()
        self.rej = Rejections("simworld")
        block = zenoh.CongestionControl.BLOCK
        z = session
        self.ros2 = None
        if ros2_domain_id is not None and isinstance(node, Ros2World):
            self.ros2 = WorldRos2(z, ros2_domain_id, node, self.inbox.callback)
        self.pub_clock = z.declare_publisher(k.clock, congestion_control=block)
        # The record's input: kept and numbered, so the monitor recovers a truth that was lost (advanced pub/sub).
        self.pub_truth = ext.declare_advanced_publisher(
            z, k.truth, congestion_control=block, cache=ext.CacheConfig(max_samples=node.timing.truth_cache_ticks),
            sample_miss_detection=ext.MissDetectionConfig(heartbeat=None,
                                                          sporadic_heartbeat=node.timing.truth_heartbeat_s))
        self.pub_state = {} if self.ros2 else {a: z.declare_publisher(k.state(a), congestion_control=block)
                                                for a in node.ids}
        self.pub_scan = {} if not self.ros2 else {a: z.declare_publisher(k.scan(a), congestion_control=block)
                                                   for a in node.ids}
        # Admission: commands (in ROS 2 mode cmd_vel) only from each agent's own session, bounded, for ticks we
        # published, one per agent and tick; an agent is alive while its token is there AND its commands keep
        # coming (a token alone can be forged), and a token without commands does not hold a lockstep tick up
        # beyond a grace longer than an agent's own wait for its peers (Membership.awaited). Our own session
        # losing its router is no agent's loss (Uplink, Membership.link).
        self.gate = Gate(node.s, "simworld")
        self.members = Membership(confirm_s=node.timing.token_confirm_s,
                                  await_grace_s=node.timing.agent_wait_timeout_s + 1.0)
        self.uplink = Uplink(session, "simworld")
        self.told: dict[int, bool] = {}
        self.pub_report = z.declare_publisher(k.report("simworld"))
        self.subs = [*([] if self.ros2 else [z.declare_subscriber(k.all_agents("cmd"), self.inbox.handler())]),
                     z.liveliness().declare_subscriber(k.alive_all, self.inbox.handler(), history=True)]
        self.token = z.liveliness().declare_token(k.alive_simworld)

    def handle(self, key: str, payload: bytes, kind: str, source: str, at_s: float) -> None:
        """A sample, as of the time it arrived (commands are taken in batches: their latency counts from then)."""
        now, sim = at_s, self.node.k * self.node.s.meta.dt_s
        if self.ros2 is not None and self.ros2.owns(key):
            try:
                c = self.ros2.decode(key, payload)
            except (ros2.Ros2Error, WireError) as exc:
                self.rej.reject(key, str(exc))
                self.node.rejected = self.rej.count
                return
            self.gate.world_k, self.gate.t = self.node.k, sim  # (sim: the intrusions' first_t)
            if self.gate.admit_twist(c, source, key, now):  # bounded, from agent i's own session
                self.members.data(c.id, now, sim)
                if not self.told.get(c.id) and self.members.alive(c.id, now, sim):
                    self.sync(now)
                self.ros2.command(c, now)
            return
        try:
            what, aid, leaf = self.keys.parse(key)
            if what == "alive":
                if leaf == "monitor":
                    self.node.monitor_up(kind != "DELETE")
                elif leaf == "agent" and aid is not None:
                    self.members.token(aid, kind != "DELETE", now, sim)
                    self.sync(now)
            elif what == "agent" and leaf == "cmd" and aid is not None:
                c = wire.cmd_from_wire(payload, aid)
                self.gate.world_k, self.gate.t = self.node.k, sim  # (sim: the intrusions' first_t)
                if self.gate.admit(c, source, key, now):
                    self.members.data(c.id, now, sim)
                    if not self.told.get(c.id) and self.members.alive(c.id, now, sim):
                        self.sync(now)
                    self.node.command(c, now)
        except WireError as exc:
            self.rej.reject(key, str(exc))
            self.node.rejected = self.rej.count

    def sync(self, now: float) -> None:
        """Tell the node who is alive by the membership rule (token AND own commands or cmd_vel), as it changes."""
        node = self.node
        sim = node.k * node.s.meta.dt_s
        if node.started:
            self.members.start(now, sim)
        if node.phase is Phase.WAIT_COMMANDS and node.deadline_s is not None:  # (since the tick went out)
            for aid in node.missing():
                self.members.awaited(aid, node.deadline_s - node.timing.step_timeout_s, now)
        for aid in self.node.ids:
            up = self.members.alive(aid, now, sim)
            if self.told.get(aid, False) != up:
                self.told[aid] = up
                self.node.agent_up(aid, up)

    def report(self, final: bool = False) -> None:
        r = self.gate.report(time.monotonic(), final)
        if r is not None:
            self.pub_report.put(report_to_wire(r))

    def put(self, out: TickOut) -> None:
        self.pub_clock.put(wire.clock_to_wire(out.clock))
        self.pub_truth.put(wire.truth_to_wire(out.truth))
        self.node.sent(out.clock.k, time.monotonic())
        if self.ros2 is not None:
            self.ros2.publish(out.states)
            for _ in range(self.ros2.new_bad_attachments()):
                self.rej.reject("/robot_<i>/cmd_vel", "a sample without a valid rmw_zenoh attachment")
            self.node.rejected = self.rej.count
            for m in out.states:
                if m.scan is not None:
                    self.pub_scan[m.id].put(wire.scan_to_wire(m.scan))
            return
        for m in out.states:
            self.pub_state[m.id].put(wire.state_to_wire(m))

    def run(self, stop: Stopper) -> str:
        """Feed the node until it ends the mission; returns the end reason."""
        wake_s, want = time.monotonic(), self.node.awaiting()
        mark = StartMark()
        while True:
            mark(self.node.started)
            # One wake-up per batch: the commands the tick waits for, or its due time, or 50 ms at most.
            items = self.inbox.take(want, min(0.05, max(0.0, wake_s - time.monotonic())))
            now = time.monotonic()
            if self.node.stalled(now):  # we did not run: tokens may flap for a while (the node sees it at its step)
                self.members.settle(now + self.node.timing.peer_silent_s)
            if (change := self.uplink.poll()) is not None:
                self.members.link(change is LinkChange.UP, now, self.node.k * self.node.s.meta.dt_s,
                                  self.node.timing.relink_settle_s)
                self.node.link(change is LinkChange.UP, now)
            for item in items:
                self.handle(*item)
            self.sync(time.monotonic())
            self.report()
            st = self.node.step(time.monotonic(), stop.stopped)
            for out in st.out:
                self.put(out)
            if st.ended is not None:
                self.report(final=True)
                return st.ended
            wake_s, want = st.wake_s, self.node.awaiting()


def run(cfg: SimworldConfig) -> int:
    clock = ClockMode(cfg.clock)
    if not cfg.speed > 0:
        raise BadInput(f"--speed: must be > 0, got {cfg.speed}")
    s = load(cfg.scenario)
    timing = replace(TIMING, start_timeout_s=cfg.start_timeout_s)
    if cfg.ros2_domain_id is not None and clock != ClockMode.REALTIME:
        raise BadInput("--ros2: runs on the realtime clock only (ROS 2 topics carry no tick), not --clock lockstep")
    node = (WorldNode(s, clock, cfg.speed, timing) if cfg.ros2_domain_id is None
            else Ros2World(s, cfg.speed, timing=timing))
    with serving(cfg.zenoh, "simworld") as (session, stop):
        world = WorldAdapter(node, cfg.run_id or s.meta.name, session, cfg.ros2_domain_id)
        log.info("simworld up (run %s, %s clock): waiting for %d agents and the monitor", world.keys.run,
                 clock, len(node.ids))
        wall0 = time.monotonic()
        reason = world.run(stop)
        if not node.started:
            return 0
        log.info("mission ended (%s) after %.2f s wall; stats %s", reason, time.monotonic() - wall0, node.stats())
        time.sleep(TIMING.world_end_linger_s)  # let the last messages reach the monitor before the session closes
        world.close()
        return 0
