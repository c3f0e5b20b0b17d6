"""Fault specifications for `deploy/run_local.sh --fault SPEC` (repeatable).

    ACTION[:TARGET]@T[+DURATION]

T is simulated seconds (when the clock reaches T), DURATION wall seconds. Actions:

    kill:agent:3@60          SIGKILL agent 3
    freeze:agent:2@50+5      SIGSTOP agent 2, SIGCONT 5 s later
    restart:agent:4@70+1     SIGKILL agent 4, start it again 1 s later (default 1 s)
    kill:monitor@80          SIGKILL the monitor (run_local.sh restarts it; it appends to run.db)
    freeze:simworld@40+10    SIGSTOP the world, SIGCONT 10 s later (recorded as one world_stalled event)
    kill:simworld@40         SIGKILL the world (the run ends: world_lost recorded and printed, exit 3)
    kill:router@90           SIGKILL the router (run_local.sh restarts it at once on the same endpoint)
    restart:router@90+2      SIGKILL the router, start it again 2 s later (default 1 s)
    flood@30                 10,000 malformed payloads on every key of the run (flood:N@T for N)
    partition@40+10          cut the link between the two hosts of a two-host run for 10 s
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from reconswarm.errors import BadInput
from reconswarm.scenario.wire_limits import MAX_AGENT_ID, agent_id_from_text

ACTIONS = {"kill", "freeze", "restart", "flood", "partition"}
_PROCESS_ACTIONS = {"monitor": ("kill", "restart", "freeze"), "router": ("kill", "restart", "freeze"),
                    "simworld": ("kill", "freeze")}  # what may be done to the one process of each role
_SPEC = re.compile(r"^(?P<action>[a-z]+)(?::(?P<target>[a-z]+|\d+))?(?::(?P<id>\d+))?@(?P<t>\d+(?:\.\d+)?)"
                   r"(?:\+(?P<dur>\d+(?:\.\d+)?))?$", re.ASCII)  # (ASCII: \d takes any Unicode digit otherwise)


@dataclass(frozen=True)
class Fault:
    action: str
    target: str  # agent | monitor | router | simworld | "" (flood, partition)
    agent_id: int | None
    at_s: float  # simulated time
    duration_s: float  # wall seconds (freeze, restart delay, partition)
    count: int = 10_000  # flood: messages

    def describe(self) -> str:
        who = f"{self.target} {self.agent_id}" if self.agent_id is not None else self.target or "the run"
        return f"{self.action} {who} at t={self.at_s:g} s" + (f" for {self.duration_s:g} s" if self.duration_s else "")


def parse(spec: str) -> Fault:
    m = _SPEC.match(spec.strip())
    if not m:
        raise BadInput(f"--fault {spec!r}: expected ACTION[:TARGET[:ID]]@T[+DURATION], e.g. kill:agent:3@60")
    action, target, aid = m["action"], m["target"] or "", m["id"]
    t, dur = float(m["t"]), float(m["dur"]) if m["dur"] else 0.0
    if action not in ACTIONS:
        raise BadInput(f"--fault {spec!r}: unknown action {action!r} (one of {', '.join(sorted(ACTIONS))})")
    if action == "flood":
        count = int(target) if target.isdigit() else 10_000
        return Fault("flood", "", None, t, 0.0, count)
    if action == "partition":
        return Fault("partition", "", None, t, dur or 10.0)
    if target == "agent":
        if aid is None:
            raise BadInput(f"--fault {spec!r}: which agent? e.g. {action}:agent:3@{t:g}")
        agent_id = agent_id_from_text(aid)
        if agent_id is None:
            raise BadInput(f"--fault {spec!r}: agent ids are 0..{MAX_AGENT_ID}, written without leading zeros")
    elif action in _PROCESS_ACTIONS.get(target, ()):
        agent_id = None
    else:
        raise BadInput(f"--fault {spec!r}: {action} needs a target: agent:ID, monitor, router"
                       + (" or simworld" if action in ("kill", "freeze") else ""))
    if action == "freeze" and not dur:
        raise BadInput(f"--fault {spec!r}: freeze needs a duration, e.g. freeze:agent:2@{t:g}+5")
    if action == "restart" and not dur:
        dur = 1.0
    return Fault(action, target, agent_id, t, dur)
