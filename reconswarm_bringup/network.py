"""Where a run's routers go and how each process reaches one: plain, secure (mutual TLS) or two hosts."""

from __future__ import annotations

import logging
import math
import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from reconswarm.errors import BadInput, ProcessFailure
from reconswarm.net.runtime.session import DEFAULT_ROUTER, ZenohOptions
from reconswarm.scenario.model import Scenario
from reconswarm_bringup import netns, packing, runid, secure_net
from reconswarm_bringup.config import LaunchConfig
from reconswarm_bringup.endpoints import addresses, host_port

log = logging.getLogger("reconswarm.launch")


def _port_free(endpoint: str) -> bool:
    """Whether nothing listens on the endpoint: a bind on every address its host resolves to, each in its own
    address family (an IPv4 socket cannot even bind `::1`, which looked like "in use")."""
    hp = host_port(endpoint)
    if hp is None:
        return True
    for family, sockaddr in addresses(*hp):
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind(sockaddr)
            except OSError:
                return False
    return True


def listening(host: str, port: int) -> bool:
    """Something listens on host:port (found by a bind, without connecting to it)."""
    return not _port_free(f"tcp/{'[' + host + ']' if ':' in host else host}:{port}")


def check_live_port(cfg: LaunchConfig) -> None:
    """--foxglove PORT: not the router's port and free on 127.0.0.1, refused before anything starts (a monitor
    that cannot serve there was started six times, then the run failed with exit 3)."""
    port = cfg.foxglove_port
    if port is None:
        return
    endpoint = cfg.router or DEFAULT_ROUTER
    hp = host_port(endpoint)
    if hp is not None and hp[1] == port:
        raise BadInput(f"--foxglove {port}: that is the router's port ({endpoint}); pass another port")
    if listening("127.0.0.1", port):
        raise BadInput(f"--foxglove {port}: 127.0.0.1:{port} is already in use; pass another port")


@dataclass
class Net:
    """Where the routers run and how each process reaches one."""

    watch: ZenohOptions  # the launcher's own session (progress, fault timing)
    routers: list[tuple[str, list[str], list[str]]]  # (id, router args, command prefix) to start
    reach: dict[tuple[str, str], tuple[list[str], list[str]]]  # (role, id) -> (prefix, zenoh args)
    default: list[str]
    hosts: Any = None
    wait_on: str | None = None  # the endpoint of the router we start here, to wait for before the rest

    def wait_router(self, alive: Callable[[], bool], timeout_s: float = 120.0) -> None:
        """Wait until our router accepts connections (on a busy machine its start takes seconds; the other
        processes are started after it, and meanwhile do not compete with it for the CPU)."""
        if self.wait_on is None:
            return
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if not _port_free(self.wait_on):  # bound (it was free before): our router listens
                return
            if not alive():
                raise ProcessFailure(f"router: exited before listening on {self.wait_on} (see logs/router.log)")
            time.sleep(0.1)
        raise ProcessFailure(f"router: not listening on {self.wait_on} after {timeout_s:.0f} s")

    def zopt(self, role: str, ident: str = "-") -> tuple[list[str], list[str]]:
        return self.reach.get((role, ident), ([], self.default))


def plan_network(cfg: LaunchConfig, s: Scenario, run: str, lock: runid.EndpointLock | None = None) -> Net:
    """How the run reaches its router(s). `lock`, when given, is taken on the endpoint first (one launch per
    router endpoint); a plain router already listening there is used only if no run's world is alive on it."""
    endpoint = cfg.router or DEFAULT_ROUTER
    hp = host_port(endpoint)
    if cfg.secure and hp is not None and ":" in hp[0]:  # zenoh 1.10.2 says "invalid dns name" for tls/[::1]:P
        raise BadInput(f"--router {endpoint} with --secure: zenoh's TLS link cannot check a router's name at an "
                       f"IPv6 address; pass tcp/127.0.0.1:PORT or a host name")
    if lock is not None and cfg.hosts == 1:
        lock.acquire(run)
    if cfg.secure:
        sn = secure_net.plan(cfg, s, run, endpoint, _port_free)
        return Net(sn.watch, sn.routers, sn.reach, [], sn.hosts, wait_on=sn.endpoint)
    if cfg.hosts == 2:
        hosts = netns.TwoHosts.for_run(os.getpid())
        hosts.create()
        netns.ACTIVE.append(hosts)
        port = endpoint.rpartition(":")[2]
        ep_a, ep_b = f"tcp/{hosts.ip_a}:{port}", f"tcp/{hosts.ip_b}:{port}"
        on_b = [a.id for a in s.agents][len(s.agents) // 2:]
        reach = {("agent", str(a)): (hosts.exec_prefix(), ["--connect", ep_b]) for a in on_b}
        routers = [("A", ["router", "--listen", ep_a], []),
                   ("B", ["router", "--listen", ep_b, "--connect", ep_a], hosts.exec_prefix())]
        log.info("two hosts: A (this namespace, router %s: simworld, monitor, agents %s) and B (%s, router %s: "
                 "agents %s)", ep_a, [a.id for a in s.agents if a.id not in on_b], hosts.ns_b, ep_b, on_b)
        return Net(ZenohOptions.build([ep_a], None, "client", None), routers, reach, ["--connect", ep_a], hosts)
    if _port_free(endpoint):
        routers = [("-", ["router", "--listen", endpoint], [])]
    elif cfg.router is None:
        raise ProcessFailure(f"router: {endpoint} is in use (another run?); stop it or pass --router EP")
    else:
        runid.refuse_if_live(endpoint)
        log.info("using the router already listening on %s (no run's world is alive on it)", endpoint)
        routers = []
    mode = zenoh_mode(cfg, len(s.agents))
    if mode == "peer":
        log.info("zenoh: the processes as peers (samples straight from process to process on 127.0.0.1; the router "
                 "%s for discovery and outside tools)", endpoint)
    return Net(ZenohOptions.build([endpoint], None, "client", None), routers, {},
               ["--connect", endpoint, *peer_args(mode)], wait_on=endpoint if routers else None)


PEER_LISTEN = "tcp/127.0.0.1:0"  # a peer's own endpoint: loopback, a port of the system's choosing
AUTO_PEER_PROCESSES = 8  # `--zenoh-mode auto`: peers up to this many processes of a run (the router's not counted)


def zenoh_mode(cfg: LaunchConfig, n_agents: int) -> str:
    """The processes' zenoh mode for `--zenoh-mode`: `auto` is peer for agent hosts (K > 1) in a plain run on one host
    of at most 8 processes (the world, the monitor, the hosts), client otherwise: every pair of peers holds a link,
    and each sample goes out once per subscribing process (measured on 2 CPUs: docs/benchmarks.md)."""
    if cfg.zenoh_mode != "auto":
        return cfg.zenoh_mode
    k = packing.per_process(cfg.agents_per_process, n_agents)
    processes = 2 + math.ceil(n_agents / k)
    return "peer" if k > 1 and processes <= AUTO_PEER_PROCESSES and not cfg.secure and cfg.hosts == 1 else "client"


def peer_args(mode: str) -> list[str]:
    """The run's processes' own zenoh options for `--zenoh-mode`: as peers, each listens on a loopback port of its
    own and learns the others' from the router (zenoh's gossip), so samples go straight from process to process
    (as rmw_zenoh's nodes do); the router stays for discovery and for outside tools. As clients: none."""
    return ["--mode", "peer", "--listen", PEER_LISTEN] if mode == "peer" else []
