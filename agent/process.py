"""`reconswarm agent --id I` (or `--ids 1-5,9`): one agent, or several, as one process on one zenoh session.

Every hosted agent keeps its own identity on the wire (agent/hosted.py: its keys, liveliness token, gate,
counters and report), so nobody outside can tell a hosted agent from a lone one; the process's session,
subscriptions and loop are agent/host.py's, and each agent's logic is its AgentNode (agent/node.py).
When a node asks for a new session, the session is replaced and every node, with everything it knows,
is kept.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

from agent.host import RECONNECT, AgentHost
from agent.hosted import HostedAgent
from agent.node import AgentNode
from agent.robot_io import keys_robot
from agent.ros2_io import ros2_robot
from reconswarm.errors import BadInput
from reconswarm.net.runtime.inbox import Inbox, Rejections
from reconswarm.net.runtime.session import ZenohOptions, serving
from reconswarm.net.timing import TIMING, Timing
from reconswarm.net.trust.admission import Admission
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.model import load
from reconswarm.scenario.wire_limits import MAX_AGENT_ID, MAX_IDS, agent_id_from_text

__all__ = ["AgentConfig", "HostedAgent", "parse_ids", "run"]
log = logging.getLogger("reconswarm.agent")


@dataclass(frozen=True)
class AgentConfig:
    agent_ids: tuple[int, ...]  # the agents this process hosts (one: a lone agent)
    scenario: Path
    zenoh: ZenohOptions
    run_id: str | None = None
    timing: Timing = TIMING
    ros2_domain_id: int | None = None  # ROS 2 mode: odom in, cmd_vel out (agent/ros2_io.py) in this domain


def parse_ids(ids: list[str] | None, spec: str | None) -> tuple[int, ...]:
    """`--id I` (repeatable) and `--ids 1-5,9` as one ordered tuple of distinct ids (at most MAX_IDS, as many as a
    scenario holds, counted before any list is built); bad input: BadInput."""
    spans = []
    for text in ids or []:
        a = agent_id_from_text(text.strip())
        if a is None:
            raise BadInput(f"--id: expected an agent id (0..{MAX_AGENT_ID}), got {text!r}")
        spans.append(range(a, a + 1))
    for part in (spec or "").split(",") if spec is not None else []:
        lo, dash, hi = part.strip().partition("-")
        a, b = agent_id_from_text(lo), agent_id_from_text(hi) if dash else agent_id_from_text(lo)
        if a is None or b is None:
            raise BadInput(f"--ids: expected ids (0..{MAX_AGENT_ID}) and ranges such as 1-5,9, got {spec!r}")
        if b < a:
            raise BadInput(f"--ids: bad range {part.strip()!r} in {spec!r}")
        spans.append(range(a, b + 1))
    if sum(len(r) for r in spans) > MAX_IDS:
        raise BadInput(f"--id/--ids: more than {MAX_IDS} agents (a scenario's most) in {spec!r}")
    out = [a for r in spans for a in r]
    if not out:
        raise BadInput("--id or --ids: which agent(s)? e.g. --id 3 or --ids 1-5,9")
    return tuple(dict.fromkeys(out))


def _who(ids: tuple[int, ...]) -> str:
    return f"agent {ids[0]}" if len(ids) == 1 else f"agents {','.join(map(str, ids))}"


def run(cfg: AgentConfig) -> int:
    s = load(cfg.scenario)
    ids = cfg.agent_ids
    missing = [a for a in ids if a not in {a.id for a in s.agents}]
    if missing:
        raise BadInput(f"--id: agent {missing[0]} is not in {cfg.scenario}")
    # Kept across new sessions: each agent's node, gate and rejection count.
    nodes = {a: AgentNode(s, a, time.monotonic(), cfg.timing) for a in ids}
    # One admission for the process's agents (who speaks for whom, where each peer was, whether a hull lies on its
    # obstacle): the host judges each sample once for all it is for; each agent's gate counts its refusals.
    adm = Admission(s)
    gates = {a: Gate(s, f"agent-{a}", adm=adm) for a in ids}
    rejs = {a: Rejections(f"agent {a}") for a in ids}
    keys = Keys(cfg.run_id or s.meta.name)
    who = _who(ids)
    # Our robots' interface, chosen once: the project's keys, or ROS 2 topics (agent/robot_io.py).
    robot = keys_robot if cfg.ros2_domain_id is None else ros2_robot(cfg.ros2_domain_id)
    zid: str | None = None  # our session's id, kept by the sessions that replace it
    while True:
        with serving(cfg.zenoh, who, cfg.timing.session_open_timeout_s, zid) as (session, stop):
            zid = str(session.info.zid())
            inbox = Inbox(ordered=True)  # (the link's order: see agent/neighbours.py)
            own = zid if len(ids) > 1 else None  # co-hosted agents hear us through it
            links = {a: HostedAgent(nodes[a], keys, session, rejs[a], gates[a], robot, own,
                                  inbox.callback(("own", a), urgent=True)) for a in ids}
            host = AgentHost(session, keys, links, inbox)
            log.info("%s up (run %s)", who, keys.run)
            code = host.run(stop, who)
            if any(n.ended for n in nodes.values()) and not stop.stopped:
                time.sleep(cfg.timing.agent_end_linger_s)  # let the monitor see the end before our tokens go
            host.close()
            if code != RECONNECT:
                for a, node in nodes.items():
                    log.info("agent %d done: last tick %d, %d messages rejected, %d intrusions refused", a, node.k,
                             node.rejected, gates[a].count)
                return code
            # A node stopped acting although the mission goes on (seen after a router restart: a route to one of
            # its keys was not restored): a new session re-declares everything; each node keeps all it knows
            # (peers' last positions, lost peers, knowledge, revisions, escape state). It has the old one's id
            # (which the old one, closed, gave back): whoever pinned our agents to that session (admission.Pins)
            # keeps hearing them, even one that takes the old session's last samples late (after its own stall).
            n = min(nodes.values(), key=lambda n: n.last_act)
            log.warning("agent %d: no command for %.0f s%s: opening a new session%s", n.id,
                        time.monotonic() - n.last_act, " (the world's token gone)" if n.world_gone else "",
                        f" (for {who}: one session)" if len(ids) > 1 else "")
            for n in nodes.values():
                n.reconnected(time.monotonic())
