"""Two hosts on one machine for `run_local.sh --hosts 2`: this network namespace is host A, a new one
host B, joined by a veth pair; each host runs its own zenoh router, and B's router connects to A's. The
partition fault takes the link down (`cut`) and up again (`heal`). Needs CAP_NET_ADMIN (root).
"""

from __future__ import annotations

import os
import subprocess
from dataclasses import dataclass

from reconswarm.errors import ProcessFailure


def _ip(*args: str, ns: str | None = None) -> subprocess.CompletedProcess[str]:
    cmd = ["ip", *(["netns", "exec", ns, "ip"] if ns else []), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=10)


def available() -> tuple[bool, str]:
    """Whether network namespaces can be made here, and why not."""
    try:
        probe = f"rsprobe{os.getpid()}"
        p = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return False, f"iproute2 not usable: {exc}"
    if p.returncode != 0:
        return False, f"network namespaces not permitted: {p.stderr.strip() or p.stdout.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True, timeout=10)
    return True, ""


@dataclass(frozen=True)
class TwoHosts:
    ns_b: str  # host B's namespace (host A is the namespace run_local.sh runs in)
    veth_a: str
    veth_b: str
    ip_a: str
    ip_b: str

    @staticmethod
    def for_run(tag: int) -> TwoHosts:
        """Names and a /30 subnet derived from a tag (e.g. the launcher's pid), so runs do not collide."""
        tag %= 16000
        a, b = tag // 64, (tag % 64) * 4
        return TwoHosts(f"rs-b-{tag}", f"rsa{tag}", f"rsb{tag}", f"10.201.{a}.{b + 1}", f"10.201.{a}.{b + 2}")

    def create(self) -> None:
        ok, why = available()
        if not ok:
            raise ProcessFailure(f"--hosts 2: {why}")
        steps = [
            ["netns", "add", self.ns_b],
            ["link", "add", self.veth_a, "type", "veth", "peer", "name", self.veth_b],
            ["link", "set", self.veth_b, "netns", self.ns_b],
            ["addr", "add", f"{self.ip_a}/30", "dev", self.veth_a],
            ["link", "set", self.veth_a, "up"],
        ]
        for args in steps:
            self._run(*args)
        for args in (["addr", "add", f"{self.ip_b}/30", "dev", self.veth_b], ["link", "set", self.veth_b, "up"],
                     ["link", "set", "lo", "up"]):
            self._run(*args, ns=self.ns_b)

    def _run(self, *args: str, ns: str | None = None) -> None:
        p = _ip(*args, ns=ns)
        if p.returncode != 0:
            self.delete()
            raise ProcessFailure(f"--hosts 2: ip {' '.join(args)}: {p.stderr.strip()}")

    def exec_prefix(self) -> list[str]:
        """Prefix a command with this to run it on host B."""
        return ["ip", "netns", "exec", self.ns_b]

    def cut(self) -> None:
        _ip("link", "set", self.veth_b, "down", ns=self.ns_b)
        _ip("link", "set", self.veth_a, "down")

    def heal(self) -> None:
        _ip("link", "set", self.veth_a, "up")
        _ip("link", "set", self.veth_b, "up", ns=self.ns_b)

    def delete(self) -> None:
        _ip("link", "del", self.veth_a)
        subprocess.run(["ip", "netns", "del", self.ns_b], capture_output=True, timeout=10)


ACTIVE: list[TwoHosts] = []  # the launcher's two-host setup, for the partition fault


def cut() -> None:
    for h in ACTIVE:
        h.cut()


def heal() -> None:
    for h in ACTIVE:
        h.heal()
