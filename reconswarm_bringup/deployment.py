"""Where a secure swarm's processes run: a deployment (hosts, each with its router endpoint and its agents; the
world's and the monitor's host), read from a TOML file (`reconswarm credentials DEPLOYMENT.toml`) or built by
the local launcher (`run_local.sh --secure`, one host, or two with `--hosts 2`).

A deployment file (docs/security.md):

    run = "paper"                 # the key prefix swarm/<run> every process of the swarm is started with
    world = "A"                   # the host of simworld
    monitor = "A"                 # the host of the monitor
    agents_per_process = 1        # optional: up to K agents in one process (one certificate naming them)
    ros2_domain = 0               # optional: the ROS 2 keys of --ros2 at this ROS_DOMAIN_ID are granted
    live_view = false             # optional: the monitor serves the live view (--foxglove)

    [[host]]
    name = "A"
    router = "tls/192.168.1.10:7450"   # where this host's router listens (and the others connect)
    agents = [1, 2, 3, 4, 5]

A bad file is refused with one line naming the file and the field (`BadInput`).
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from reconswarm.errors import BadInput
from reconswarm.net.ros2.ros2 import MAX_DOMAIN_ID
from reconswarm.scenario.toml_reader import TableReader, kind_of
from reconswarm.scenario.wire_limits import MAX_AGENT_ID
from reconswarm_bringup import packing
from reconswarm_bringup.validate import endpoint as check_endpoint

# (matched whole with fullmatch: '$' would also match before a trailing newline)
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,62}")  # a host name in file names and certificate names
_RUN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,127}")  # one key chunk: no '/', '*', '$', '?', '#'
_LOOPBACK = ("localhost", "127.0.0.1", "::1")  # one socket, whichever name a file gives it


@dataclass(frozen=True)
class Host:
    """One machine: its router's endpoint (`tls/HOST:PORT`) and the agents started there, packed into processes."""

    name: str
    router: str
    agents: tuple[int, ...]
    agent_processes: tuple[tuple[int, ...], ...]  # the agents of each agent process, in order

    @property
    def router_name(self) -> str:
        """The router's certificate common name (its ACL subject on the other routers)."""
        return f"router-{self.name}"


@dataclass(frozen=True)
class Deployment:
    run: str  # the key prefix is swarm/<run>
    hosts: tuple[Host, ...]
    world_host: str
    monitor_host: str
    ros2_domain: int | None = None
    live_view: bool = False

    @property
    def agent_ids(self) -> tuple[int, ...]:
        return tuple(a for h in self.hosts for a in h.agents)

    def host(self, name: str) -> Host:
        for h in self.hosts:
            if h.name == name:
                return h
        raise BadInput(f"deployment: no host {name!r}")

    def host_of_agent(self, agent_id: int) -> Host:
        for h in self.hosts:
            if agent_id in h.agents:
                return h
        raise BadInput(f"deployment: no host runs agent {agent_id}")


def tls_endpoint(endpoint: str) -> str:
    """`tcp/HOST:PORT` (or `tls/HOST:PORT`) -> `tls/HOST:PORT`; anything else is refused."""
    proto, sep, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    if not sep or proto not in ("tcp", "tls") or not host or not port.isdigit():
        raise BadInput(f"--secure: the router endpoint must be tcp/HOST:PORT, got {endpoint!r}")
    return f"tls/{addr}"


def same_socket(host: str, port: int) -> tuple[str, int]:
    """A router's (host, port) as a socket: host names without case, every name of the loopback as one."""
    h = host.strip("[]").lower()
    return ("localhost" if h in _LOOPBACK else h), port


def local(run: str, hosts: list[tuple[str, str, tuple[int, ...]]], per_process: int,
          ros2_domain: int | None = None, live_view: bool = False) -> Deployment:
    """The local launcher's deployment: (name, router endpoint, agents) per host; world and monitor on the first."""
    built = tuple(Host(name, tls_endpoint(ep), ids, tuple(packing.hosts(ids, max(1, per_process), lambda a: "")))
                  for name, ep, ids in hosts)
    return Deployment(run, built, built[0].name, built[0].name, ros2_domain, live_view)


def load(path: Path) -> Deployment:
    """Read a deployment file; BadInput naming the file and the field on any problem."""
    src = str(path)
    try:
        data = tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise BadInput(f"{src}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInput(f"{src}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise BadInput(f"{src}: not valid TOML: {exc}") from None
    return parse(data, src)


def parse(data: dict[str, Any], src: str = "<deployment>") -> Deployment:
    r = TableReader(src)
    r.keys(data, "", {"run", "world", "monitor", "host"}, {"agents_per_process", "ros2_domain", "live_view"})
    run = r.string(data, "", "run")
    if not _RUN.fullmatch(run):
        raise r.fail("run", f"one key chunk of letters, digits, '_', '.', '-' expected, got {run!r}")
    k = r.integer(data, "", "agents_per_process", 1, lo=1)
    domain = None
    if "ros2_domain" in data:
        domain = r.integer(data, "", "ros2_domain", lo=0)
        if domain > MAX_DOMAIN_ID:
            raise r.fail("ros2_domain", f"must be <= {MAX_DOMAIN_ID}, got {domain}")
    live_view = data.get("live_view", False)
    if not isinstance(live_view, bool):
        raise r.fail("live_view", f"expected true or false, got {kind_of(live_view)}")
    raw = data["host"]
    if not isinstance(raw, list) or not raw:
        raise r.fail("host", "expected one [[host]] table or more")
    hosts: list[Host] = []
    seen_agents: dict[int, str] = {}
    seen_routers: dict[tuple[str, int], str] = {}
    for n, h in enumerate(raw):
        where = f"host[{n}]"
        h = r.table(h, where)
        r.keys(h, where, {"name", "router", "agents"}, set())
        name = r.string(h, where, "name")
        if not _NAME.fullmatch(name):
            raise r.fail(f"{where}.name", f"letters, digits, '_', '.', '-' expected, got {name!r}")
        if any(x.name == name for x in hosts):
            raise r.fail(f"{where}.name", f"host {name!r} is named twice")
        ep = r.string(h, where, "router")
        try:
            proto, addr, port = check_endpoint(f"{where}.router", ep)
        except BadInput as exc:
            raise BadInput(f"{src}: {exc}") from None
        if proto not in ("tls", "tcp") or "?" in ep or "#" in ep:
            raise r.fail(f"{where}.router", f"expected tls/HOST:PORT, got {ep!r}")
        if ":" in addr:  # zenoh 1.10.2 says "invalid dns name" for tls/[::1]:P
            raise r.fail(f"{where}.router", f"zenoh's TLS link cannot check a router's name at an IPv6 address "
                                            f"({ep!r}): give an IPv4 address or a host name")
        ep = tls_endpoint(ep)
        sock = same_socket(addr, port)
        if sock in seen_routers:
            raise r.fail(f"{where}.router", f"{ep} is also host {seen_routers[sock]!r}'s router")
        seen_routers[sock] = name
        agents = h["agents"]
        if not isinstance(agents, list):
            raise r.fail(f"{where}.agents", f"expected a list of agent ids, got {kind_of(agents)}")
        ids: list[int] = []
        for j, a in enumerate(agents):
            if isinstance(a, bool) or not isinstance(a, int) or not 0 <= a <= MAX_AGENT_ID:
                raise r.fail(f"{where}.agents[{j}]",
                             f"expected an agent id (an integer in [0, {MAX_AGENT_ID}], the wire's), got {a!r}")
            if a in seen_agents:
                raise r.fail(f"{where}.agents[{j}]", f"agent {a} is also on host {seen_agents[a]!r}")
            seen_agents[a] = name
            ids.append(a)
        hosts.append(Host(name, ep, tuple(ids), tuple(packing.hosts(ids, k, lambda a: "")) if ids else ()))
    names = [h.name for h in hosts]
    for key in ("world", "monitor"):
        v = r.string(data, "", key)
        if v not in names:
            raise r.fail(key, f"no host named {v!r} (hosts: {', '.join(names)})")
    if not seen_agents:
        raise r.fail("host", "no host runs an agent")
    return Deployment(run, tuple(hosts), data["world"], data["monitor"], domain, live_view)
