"""`reconswarm simworld`: the world process, a thin zenoh adapter around `simworld.world.WorldNode`.

It decodes commands and liveliness changes into the node, calls `WorldNode.step` with the time, and
puts what the step returns (clock, truth, states, scans) on the wire. The tick logic (readiness
barrier, lockstep and realtime clocks, re-publish, hold-then-stop, strikes) is in world.py.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path

import zenoh

from reconswarm.errors import BadInput
from reconswarm.net import wire
from reconswarm.net.session import Inbox, Member, Rejections, Stopper, ZenohOptions, serving
from reconswarm.net.timing import TIMING
from reconswarm.net.wire import ClockMode
from reconswarm.scenario import load
from simworld.world import TickOut, WorldNode

log = logging.getLogger("reconswarm.simworld")


@dataclass(frozen=True)
class SimworldConfig:
    """The world process's options (the scenario's own [world] section is `scenario.WorldConfig`)."""

    scenario: Path
    zenoh: ZenohOptions
    clock: ClockMode = ClockMode.LOCKSTEP
    speed: float = 10.0
    run_id: str | None = None
    start_timeout_s: float = TIMING.start_timeout_s


class WorldAdapter(Member):
    """Moves bytes between zenoh and the node: decode in, encode out."""

    def __init__(self, node: WorldNode, run: str, session: zenoh.Session) -> None:
        self.node = node
        self.keys = k = wire.Keys(run)
        self.inbox = Inbox()
        self.rej = Rejections("simworld")
        block = zenoh.CongestionControl.BLOCK
        z = session
        self.pub_clock = z.declare_publisher(k.clock, congestion_control=block)
        self.pub_truth = z.declare_publisher(k.truth, congestion_control=block)
        self.pub_state = {a: z.declare_publisher(k.state(a), congestion_control=block) for a in node.ids}
        self.pub_scan = {a: z.declare_publisher(k.scan(a), congestion_control=block) for a in node.ids}
        self.subs = [z.declare_subscriber(k.all_agents("cmd"), self.inbox.callback),
                     z.liveliness().declare_subscriber(k.alive_all, self.inbox.callback, history=True)]
        self.token = z.liveliness().declare_token(k.alive_simworld)

    def handle(self, key: str, payload: bytes, kind: str) -> None:
        try:
            what, aid, leaf = self.keys.parse(key)
            if what == "alive":
                if leaf == "monitor":
                    self.node.monitor_up(kind != "DELETE")
                elif leaf == "agent" and aid is not None:
                    self.node.agent_up(aid, kind != "DELETE")
            elif what == "agent" and leaf == "cmd" and aid is not None:
                self.node.command(wire.cmd_from_wire(payload, aid), time.monotonic())
        except wire.WireError as exc:
            self.rej.reject(key, str(exc))
            self.node.rejected = self.rej.count

    def put(self, out: TickOut) -> None:
        self.pub_clock.put(wire.clock_to_wire(out.clock))
        self.pub_truth.put(wire.truth_to_wire(out.truth))
        self.node.sent(out.clock.k, time.monotonic())
        for m in out.states:
            self.pub_state[m.id].put(wire.state_to_wire(m))
        for sc in out.scans:
            self.pub_scan[sc.id].put(wire.scan_to_wire(sc))

    def run(self, stop: Stopper) -> str:
        """Feed the node until it ends the mission; returns the end reason."""
        while True:
            for item in self.inbox.drain():
                self.handle(*item)
            st = self.node.step(time.monotonic(), stop.stopped)
            for out in st.out:
                self.put(out)
            if st.ended is not None:
                return st.ended
            got = self.inbox.get(min(0.05, max(0.0, st.wake_s - time.monotonic())))
            if got is not None:
                self.handle(*got)


def run(cfg: SimworldConfig) -> int:
    clock = ClockMode(cfg.clock)
    if not cfg.speed > 0:
        raise BadInput(f"--speed: must be > 0, got {cfg.speed}")
    s = load(cfg.scenario)
    node = WorldNode(s, clock, cfg.speed, replace(TIMING, start_timeout_s=cfg.start_timeout_s))
    with serving(cfg.zenoh, "simworld") as (session, stop):
        world = WorldAdapter(node, cfg.run_id or s.meta.name, session)
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
