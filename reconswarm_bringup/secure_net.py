"""Where a secure run's routers go and how each process reaches one (`run_local.sh --secure`, with `--hosts 2`,
`--ros2`, `--foxglove`): the run's deployment (one host, or hosts A and B in network namespaces) and its
credentials, made by reconswarm_bringup/secure.py as `reconswarm credentials` makes a real deployment's."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from reconswarm.errors import BadInput
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.scenario.model import Scenario
from reconswarm.scenario.wire_limits import ids_runs_text
from reconswarm_bringup import netns, packing, secure
from reconswarm_bringup.config import LaunchConfig
from reconswarm_bringup.deployment import Deployment, Host, tls_endpoint

log = logging.getLogger("reconswarm.launch")


def _deployment(cfg: LaunchConfig, s: Scenario, run: str, endpoints: list[str]) -> Deployment:
    """The agents split in order over the hosts (the second half on B), packed per --agents-per-process; the world
    and the monitor on the first host."""
    ids = [a.id for a in s.agents]
    per = packing.per_process(cfg.agents_per_process, len(ids))
    cut = 0 if len(endpoints) == 1 else len(ids) // 2
    parts = [ids[:cut], ids[cut:]] if len(endpoints) == 2 else [ids]
    names = ["A", "B"][:len(endpoints)]
    hosts = tuple(Host(n, tls_endpoint(ep), tuple(part), tuple(packing.hosts(part, per, lambda a: "")))
                  for n, ep, part in zip(names, endpoints, parts, strict=True))
    return Deployment(run, hosts, "A", "A", cfg.ros_domain_id, cfg.foxglove_port is not None)


@dataclass(frozen=True)
class SecureNet:
    """What reconswarm_bringup/network.py's Net is made of, for a secure run."""

    watch: ZenohOptions  # the launcher's watcher: the observer's rights, on A's router
    routers: list[tuple[str, list[str], list[str]]]
    reach: dict[tuple[str, str], tuple[list[str], list[str]]]
    hosts: Any  # netns.TwoHosts with --hosts 2, else None
    endpoint: str  # A's router endpoint (in this namespace: the launcher waits for it)


def plan(cfg: LaunchConfig, s: Scenario, run: str, endpoint: str, port_free: Callable[[str], bool]) -> SecureNet:
    """The secure run's network: its credentials under OUTDIR/secrets, a router per host (B's connects to A's over
    mutual TLS), each process with its own configuration. port_free(endpoint): nothing listens there."""
    hosts = None
    if cfg.hosts == 2:
        hosts = netns.TwoHosts.for_run(os.getpid())
        port = endpoint.rpartition(":")[2]
        dep = _deployment(cfg, s, run, [f"tls/{hosts.ip_a}:{port}", f"tls/{hosts.ip_b}:{port}"])
    else:
        dep = _deployment(cfg, s, run, [endpoint])
    sec = secure.write(cfg.out / "secrets", dep, intruder=True)
    if hosts is None and not port_free(sec.endpoint):  # a router already there holds another CA: it cannot serve us
        raise BadInput(f"{sec.endpoint}: in use by a router this launch did not start; secure mode starts "
                       f"its own router: pass another --router port")
    if hosts is not None:
        hosts.create()
        netns.ACTIVE.append(hosts)
    prefix = {h.name: ([] if h.name == "A" or hosts is None else hosts.exec_prefix()) for h in dep.hosts}

    def zargs(path: object) -> list[str]:
        return ["--zenoh-config", str(path)]

    reach: dict[tuple[str, str], tuple[list[str], list[str]]] = {
        ("monitor", "-"): ([], zargs(sec.config_for("monitor"))),
        ("simworld", "-"): ([], zargs(sec.config_for("simworld"))),
        ("flood", "-"): ([], zargs(sec.config_for("intruder"))),
    }
    for h in dep.hosts:
        for g in h.agent_processes:  # an agent host is reached by its first agent's id, as it starts
            ident = str(g[0]) if len(g) == 1 else ids_runs_text(g)
            for a in g:  # (every member: the launcher packs agents by where they run)
                reach[("agent", str(a))] = (prefix[h.name], zargs(sec.config_for("agent", ident)))
    routers = [(h.name if hosts is not None else "-", ["router", "--zenoh-config", str(sec.router_config_for(h.name))],
                prefix[h.name]) for h in dep.hosts]
    if hosts is not None:
        log.info("two hosts, secure: A (this namespace, router %s: simworld, monitor, agents %s) and B (%s, router %s, "
                 "connected to A's over mutual TLS: agents %s)", dep.hosts[0].router, list(dep.hosts[0].agents),
                 hosts.ns_b, dep.hosts[1].router, list(dep.hosts[1].agents))
    # the launcher's watcher: the observer's rights, on A's router (named: the ROS 2 notice shows it)
    watch = ZenohOptions.build([sec.endpoint], None, "client", sec.config_for("observer"))
    return SecureNet(watch, routers, reach, hosts, sec.endpoint)
