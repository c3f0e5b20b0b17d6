"""Fault injection for run_local.sh: real signals to real processes, real garbage on real zenoh keys.

Nothing here reaches inside a process: an agent is killed with SIGKILL, frozen with SIGSTOP/SIGCONT,
restarted as a new process; the router likewise; a flood is a separate process publishing malformed
payloads on every key of the run.
"""

from __future__ import annotations

import logging
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from reconswarm_bringup import netns
from reconswarm_bringup.faults import Fault
from reconswarm_bringup.fleet import Fleet

log = logging.getLogger("reconswarm.launch")
Timer = tuple[float, Callable[[], Any]]


def inject(f: Fault, fleet: Fleet, run: str, scenario_path: Path) -> list[Timer]:
    """Start fault f now; return the timers that finish it later (wall time, action)."""
    now = time.monotonic()
    if f.action == "flood":
        args = ["flood", "--run", run, "--count", str(f.count), "--scenario", str(scenario_path)]
        prefix, zargs = fleet.zopt("flood")
        fleet.start("flood", "-", [*args, *zargs], prefix)
        return []
    if f.action == "partition":
        netns.cut()
        return [(now + f.duration_s, netns.heal)]
    ident = str(f.agent_id) if f.agent_id is not None else "-"
    proc = fleet.find(f.target, ident)
    if proc is None or proc.popen.poll() is not None:
        log.warning("fault: %s %s is not running", f.target, ident)
        return []
    if proc.members:  # an agent host (--agents-per-process): the fault acts on its process, so on all its agents
        log.warning("fault: agent %s runs in the process of agents %s: the %s acts on all of them", ident, proc.id,
                    f.action)
        ident = proc.id
    if f.action == "kill":
        # A killed agent stays dead; a killed monitor or router is restarted by the launcher's supervision.
        proc.expected_exit = f.target == "agent"  # the world's death ends the run (exit 3)
        fleet.signal(proc, signal.SIGKILL)
        return []
    if f.action == "freeze":
        fleet.signal(proc, signal.SIGSTOP)

        def thaw() -> None:
            log.warning("fault: SIGCONT %s %s", f.target, ident)
            fleet.signal(proc, signal.SIGCONT)

        return [(now + f.duration_s, thaw)]
    if f.action == "restart":
        proc.expected_exit = True
        fleet.signal(proc, signal.SIGKILL)

        def again() -> None:
            proc.popen.wait()
            log.warning("fault: starting %s %s again", f.target, ident)
            fleet.restart(proc)

        return [(now + f.duration_s, again)]
    raise ValueError(f"unknown fault {f}")

