"""How a run's agents are packed into processes (`run_local.sh --agents-per-process K|auto`).

K = 1 (the default) is one process per agent. K > 1 packs up to K agents into one agent host
(`reconswarm agent --ids 1-5`: one zenoh session, each agent still with its own keys and token), in the
scenario's order; agents that reach the router differently (`--hosts 2`) are never packed together.
`auto`: one agent host while the swarm is small, then one per CPU: H = min(C, ceil(N / 48)) hosts of
K = ceil(N / H) agents, C the CPUs this launcher may run on. Below about 48 agents a second host costs more
than it brings: each host takes the other's beacons through the router, each admitted by every receiving agent,
and on 2 CPUs one host of 10-36 agents ran 1.2-1.6x faster in lockstep than two (the paper, the grid of 16 and
36: docs/benchmarks.md); at 64 and 100 two hosts were as fast or faster. K > N is clamped to N.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable, Sequence
from typing import Any

from reconswarm.errors import BadInput
from reconswarm.scenario.model import Scenario
from reconswarm.scenario.wire_limits import ids_runs_text
from reconswarm_bringup.fleet import allowed_cpus

log = logging.getLogger("reconswarm.launch")

AUTO = "auto"
OPTION = "--agents-per-process"


def parse(value: str) -> int | str:
    """The option's value: a positive integer or `auto` (BadInput otherwise)."""
    v = value.strip().lower()
    if v == AUTO:
        return AUTO
    if not (v.isascii() and v.isdigit()) or int(v) < 1:  # ("²".isdigit(), but int() refuses it)
        raise BadInput(f"{OPTION}: expected a positive integer or auto, got {value!r}")
    return int(v)


def cpus() -> int:
    return len(allowed_cpus()) or max(1, os.cpu_count() or 1)


AUTO_HOST_AGENTS = 48  # `auto`: agents per host before a second host pays (measured on 2 CPUs)


def per_process(k: int | str, n_agents: int, n_cpus: int | None = None) -> int:
    """K for N agents: `auto` is ceil(N / H) with H = min(CPUs, ceil(N / 48)) hosts; any K is clamped to 1..N."""
    if k == AUTO:
        n_hosts = max(1, min(n_cpus or cpus(), math.ceil(n_agents / AUTO_HOST_AGENTS)))
        want = math.ceil(n_agents / n_hosts)
    else:
        want = int(k)
    return max(1, min(want, n_agents))


def hosts(ids: Sequence[int], k: int, reach: Callable[[int], object]) -> list[tuple[int, ...]]:
    """The agents of each process: runs of up to k consecutive agents (in the scenario's order) that reach the
    router the same way."""
    out: list[tuple[int, ...]] = []
    for a in ids:
        if out and len(out[-1]) < k and reach(out[-1][0]) == reach(a):
            out[-1] = (*out[-1], a)
        else:
            out.append((a,))
    return out


def agent_args(ids: Sequence[int]) -> list[str]:
    """The agent command's arguments naming its agents: `--id I` alone (as always), `--ids SPEC` for a host."""
    return ["--id", str(ids[0])] if len(ids) == 1 else ["--ids", ids_runs_text(ids)]


def start_agents(fleet: Any, s: Scenario, k: int | str, zopt: Callable[[str, str], tuple[list[str], list[str]]],
                 args: list[str]) -> None:
    """Start the run's agents, up to K a process (`args`: the agent command's options after its ids)."""
    ids = [a.id for a in s.agents]
    per = per_process(k, len(ids))
    packed = hosts(ids, per, lambda a: zopt("agent", str(a))[0])  # (by where it runs: --hosts 2's namespaces)
    if per > 1:
        log.info("%d agents in %d process%s (%s %s: up to %d each)", len(ids), len(packed),
                 "" if len(packed) == 1 else "es", OPTION, k, per)
    if per == 1:  # (one process per agent: many light processes, which the scheduler balances best)
        fleet.cpus = ()
    elif len(fleet.cpus) > 1:
        log.info("agent host%s pinned to CPU%s %s in turn, one CPU each (--no-pin-cpus: the scheduler places them)",
                 "" if len(packed) == 1 else "s", "" if len(packed) == 1 else "s",
                 ", ".join(map(str, fleet.cpus[:len(packed)])))
    for group in packed:
        prefix, zargs = zopt("agent", str(group[0]))
        fleet.start("agent", ids_runs_text(group), ["agent", *agent_args(group), *args, *zargs], prefix,
                    members=tuple(map(str, group)) if len(group) > 1 else ())
