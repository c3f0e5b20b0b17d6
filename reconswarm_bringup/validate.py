"""Checks of command-line values before anything starts: pure functions the CLIs call (run_local.sh's
launcher, `reconswarm sweep`). Each raises BadInput with one line naming the option. (Output paths:
reconswarm/cli/outputs.py.)
"""

from __future__ import annotations

import ipaddress
import math
import re
from collections.abc import Iterable
from pathlib import Path

from reconswarm.cli.outputs import creatable_dir
from reconswarm.errors import BadInput
from reconswarm_bringup import packing
from reconswarm_bringup.faults import Fault

# Peak RSS per process of a local run, in MB: docs/benchmarks.md (bench/bench_deploy.py, medians
# at 10-50 agents); the launcher's own (a zenoh session, numpy, rich) measured at 54 MB (VmHWM, paper mission).
PEAK_RSS_MB = {"agent": 64, "monitor": 86, "simworld": 62, "router": 50, "launcher": 60}
# Each further agent of an agent host (--agents-per-process): a host of 5 paper agents peaked at 84-85 MB against
# 77-81 MB for one agent's process, ~1 MB per further agent; counted at the 10 MB per agent the issue allows.
HOSTED_AGENT_MB = 10
# Endpoints the launcher can check and start a router on: PROTO/HOST:PORT.
HOST_PORT_PROTOCOLS = ("tcp", "tls", "udp", "quic", "ws")
_HOSTNAME = re.compile(r"^[A-Za-z0-9]([A-Za-z0-9-]{0,62})(\.[A-Za-z0-9]([A-Za-z0-9-]{0,62}))*\.?$")


def positive_seconds(option: str, value: float | None) -> None:
    """A duration in seconds: finite and > 0 (None: not given)."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise BadInput(f"{option}: must be a positive number of seconds, got {value}")


def positive_finite(option: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise BadInput(f"{option}: must be a positive finite number, got {value}")


def endpoint(option: str, ep: str) -> tuple[str, str, int]:
    """A zenoh endpoint PROTO/HOST:PORT (metadata after '?' or '#' ignored) -> (proto, host, port)."""
    proto, sep, addr = ep.partition("/")
    addr = re.split(r"[?#]", addr, maxsplit=1)[0]
    if not sep or proto not in HOST_PORT_PROTOCOLS:
        raise BadInput(f"{option}: expected PROTO/HOST:PORT with PROTO one of {', '.join(HOST_PORT_PROTOCOLS)}, "
                       f"got {ep!r}")
    host, colon, port_s = addr.rpartition(":")
    if not colon or not host:
        raise BadInput(f"{option}: expected {proto}/HOST:PORT, got {ep!r}")
    if not port_s.isascii() or not port_s.isdigit() or not 1 <= int(port_s) <= 65535:
        raise BadInput(f"{option}: port must be 1..65535, got {port_s!r} in {ep!r}")
    bare = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    try:
        ipaddress.ip_address(bare)
    except ValueError:
        if host.startswith("[") or not _HOSTNAME.match(host):
            raise BadInput(f"{option}: {host!r} is neither an IP address nor a host name in {ep!r}") from None
    return proto, bare, int(port_s)


def fault_targets(faults: Iterable[Fault], agent_ids: set[int]) -> None:
    """Every --fault aimed at an agent names one of the scenario's."""
    for f in faults:
        if f.agent_id is not None and f.agent_id not in agent_ids:
            raise BadInput(f"--fault {f.describe()}: the scenario has no agent {f.agent_id}")


def agent_count(option: str, n: int) -> None:
    if n < 1:
        raise BadInput(f"{option}: must be >= 1, got {n}")


def available_memory_mb(meminfo: str | None = None) -> float | None:
    """MemAvailable from /proc/meminfo (or the given text), in MB; None if unknown."""
    if meminfo is None:
        try:
            meminfo = Path("/proc/meminfo").read_text()
        except OSError:
            return None
    m = re.search(r"^MemAvailable:\s+(\d+) kB", meminfo, re.MULTILINE)
    return int(m.group(1)) / 1024 if m else None


def run_memory_mb(n_agents: int, routers: int = 1, per_process: int = 1) -> float:
    """Peak memory of a local run: the agents' processes (up to per_process agents each), simworld, monitor, the
    routers, the launcher."""
    p, procs = PEAK_RSS_MB, math.ceil(n_agents / max(1, per_process))
    agents = procs * p["agent"] + (n_agents - procs) * HOSTED_AGENT_MB
    return agents + p["simworld"] + p["monitor"] + routers * p["router"] + p["launcher"]


def machine_holds(option: str, n_agents: int, available_mb: float | None, routers: int = 1,
                  per_process: int = 1) -> None:
    """Refuse a run whose processes need more memory than this machine has available."""
    if available_mb is None:
        return
    need = run_memory_mb(n_agents, routers, per_process)
    if need > available_mb:
        procs = math.ceil(n_agents / max(1, per_process))
        each = (f"{PEAK_RSS_MB['agent']} MB each" if per_process <= 1 else
                f"in {procs} processes: {PEAK_RSS_MB['agent']} MB a process, {HOSTED_AGENT_MB} MB each further agent")
        raise BadInput(f"{option}: {n_agents} agent{' processes' if per_process <= 1 else 's'} need about "
                       f"{_mb(need)} of memory ({each}, plus simworld, monitor, router and launcher), "
                       f"this machine has {_mb(available_mb)} available")


def _mb(v: float) -> str:
    if v >= 1024**3:
        return f"{v / 1024:.3g} GB"
    return f"{v / 1024:,.1f} GB" if v >= 1024 else f"{v:,.0f} MB"


def launch(*, agents: int | None, scenario: Path | None, out: Path, timeout_s: float | None, speed: float,
           router: str | None, hosts: int, available_mb: float | None, per_process: int | str = 1) -> None:
    """run_local.sh's arguments, before anything starts (the scenario's own size is checked once loaded,
    with `machine_holds`)."""
    if agents is not None and scenario is not None:
        raise BadInput("-n/--agents and -s/--scenario: give one (-n generates a scenario)")
    if agents is not None:
        agent_count("-n", agents)
        machine_holds(f"-n {agents}", agents, available_mb, routers=hosts,
                      per_process=packing.per_process(per_process, agents))
    positive_seconds("--timeout", timeout_s)
    positive_finite("--speed", speed)
    if router is not None:
        proto, _, _ = endpoint("--router", router)
        if proto not in ("tcp", "tls"):
            raise BadInput(f"--router: the launcher starts and checks routers on tcp/ or tls/ endpoints, "
                           f"got {router!r}")
        if "?" in router or "#" in router:  # (the router is started on, locked and probed by PROTO/HOST:PORT)
            raise BadInput(f"--router: PROTO/HOST:PORT without ?metadata or #config, got {router!r}")
    creatable_dir("-o", out)
