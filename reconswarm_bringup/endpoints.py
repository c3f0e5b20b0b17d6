"""A router endpoint as this machine sees it: its host and port, and the socket addresses the host resolves to
(`127.0.0.1`, `localhost` and `[::1]` may name the same socket, or two)."""

from __future__ import annotations

import ipaddress
import re
import socket
from typing import Any


def host_port(endpoint: str) -> tuple[str, int] | None:
    """(host, port) of a tcp/ or tls/ endpoint (brackets of an IPv6 address and any ?/# metadata removed);
    None for another protocol or no port."""
    proto, _, addr = endpoint.partition("/")
    host, _, port = re.split(r"[?#]", addr, maxsplit=1)[0].rpartition(":")
    if proto not in ("tcp", "tls") or not port.isascii() or not port.isdigit():
        return None
    return host.strip("[]"), int(port)


def addresses(host: str, port: int) -> list[tuple[socket.AddressFamily, tuple[Any, ...]]]:
    """Every socket address `host` resolves to (IPv4 and IPv6: `localhost` may be both), de-duplicated."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return []
    seen: set[tuple[Any, ...]] = set()
    out: list[tuple[socket.AddressFamily, tuple[Any, ...]]] = []
    for family, _, _, _, sockaddr in infos:
        if family in (socket.AF_INET, socket.AF_INET6) and sockaddr not in seen:
            seen.add(sockaddr)
            out.append((family, sockaddr))
    return out


def socket_names(endpoint: str) -> list[str]:
    """`ADDRESS:PORT` of every socket address the endpoint's host resolves to (an IPv4-mapped IPv6 address as
    its IPv4 one), sorted: what one launch per endpoint is decided by. The host as typed if it resolves to
    nothing (or the endpoint has no host:port)."""
    hp = host_port(endpoint)
    if hp is None:
        return [endpoint.partition("/")[2].partition("#")[0] or endpoint]
    names = set()
    for _, sockaddr in addresses(*hp):
        ip = ipaddress.ip_address(str(sockaddr[0]).partition("%")[0])
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        names.add(f"{ip}:{hp[1]}")
    return sorted(names) or [f"{hp[0]}:{hp[1]}"]
