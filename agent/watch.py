"""An agent node's safety nets, checked at each step (agent/node.py): a silent world (exit 3), no command for long (a
new session), the log while it waits, and the end of the mission once it stands."""

from __future__ import annotations

import logging
from typing import Protocol

from agent.heard import Heard
from agent.messages import Output, Reconnect
from reconswarm.net.node import Exit
from reconswarm.net.timing import Timing
from reconswarm.net.wire import wire

log = logging.getLogger("reconswarm.agent")


class Watched(Protocol):
    """What the watch reads and sets of an agent node (agent/node.py's AgentNode)."""

    id: int
    timing: Timing
    h: Heard
    started: bool
    ended: bool
    world_gone: bool
    last_act: float
    acted: float
    last_clock: float
    told_waiting: float
    clock_in: wire.Clock | None
    out: list[Output]

    def waiting_for(self) -> str: ...


def watch(node: Watched, now: float) -> None:
    """The safety nets: a silent world (exit 3), no command for long (a new session), the waiting log."""
    t = node.timing
    if not node.started and node.h.clocks:  # the mission began: the watch starts now
        node.started, node.last_act, node.acted = True, now, now
    if node.started and now - node.last_clock > t.world_silence_s:
        log.error("agent %d: no clock from the world for %.0f s", node.id, t.world_silence_s)
        node.out.append(Exit(3))
        return
    if node.started and (now - node.last_act > (t.resubscribe_world_gone_s if node.world_gone else t.resubscribe_s)
                         or now - node.acted > t.resubscribe_world_gone_s):
        node.out.append(Reconnect())
        return
    if node.started and now - node.last_act > t.waiting_log_s and now > node.told_waiting + t.waiting_log_s:
        node.told_waiting = now
        log.info("agent %d: %s", node.id, node.waiting_for())
    last = node.clock_in  # an end stands once the world's token went after it, or no clock came for a while (a
    node.ended |= last is not None and last.end and (node.world_gone or now - node.last_clock > t.end_confirm_s)
    if node.ended:  # later clock from the world, whatever tick the end claimed, says it was not the world's)
        node.out.append(Exit(0))
