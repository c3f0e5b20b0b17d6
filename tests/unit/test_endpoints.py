"""One launch per endpoint by what it resolves to, and probes in the endpoint's own address family
(issue 22, cases 6 and 7)."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from reconswarm.errors import BadInput
from reconswarm_bringup import runid
from reconswarm_bringup.endpoints import host_port, socket_names
from reconswarm_bringup.network import _port_free, listening


def _v4_loopback_names() -> set[str]:
    return {str(sa[0]) for *_, sa in socket.getaddrinfo("localhost", 1, socket.AF_INET, socket.SOCK_STREAM)}


def test_names_are_the_resolved_socket_addresses() -> None:
    assert host_port("tcp/[::1]:7600?x=1") == ("::1", 7600)
    assert host_port("udp/127.0.0.1:7600") is None
    assert socket_names("tcp/127.0.0.1:7600") == ["127.0.0.1:7600"]
    assert socket_names("tls/127.1:7600") == ["127.0.0.1:7600"]  # the same socket, however written
    assert socket_names("tcp/[::ffff:127.0.0.1]:7600") == ["127.0.0.1:7600"]
    assert socket_names("tcp/[::1]:7600") == ["::1:7600"]
    assert socket_names("tcp/no-such-host.invalid:7600") == ["no-such-host.invalid:7600"]


@pytest.mark.skipif("127.0.0.1" not in _v4_loopback_names(), reason="localhost is not 127.0.0.1 here")
def test_localhost_and_127_0_0_1_are_one_lock(tmp_path: Path) -> None:
    a = runid.EndpointLock("tcp/127.0.0.1:7600", tmp_path)
    a.acquire("paper-aaaaaa")
    try:
        with pytest.raises(BadInput, match="tcp/localhost:7600: router in use by run paper-aaaaaa"):
            runid.EndpointLock("tcp/localhost:7600", tmp_path).acquire("paper-bbbbbb")
    finally:
        a.release()
    b = runid.EndpointLock("tcp/localhost:7600", tmp_path)
    b.acquire("paper-cccccc")  # released: the next launch gets it, by either name
    b.release()


def _ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as s:
            s.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback here")
def test_ipv6_loopback_probe_uses_ipv6() -> None:
    """An IPv4 socket cannot bind ::1: the old probe took every [::1] endpoint as in use."""
    with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as s:
        s.bind(("::1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert not _port_free(f"tcp/[::1]:{port}") and listening("::1", port)
    assert _port_free(f"tcp/[::1]:{port}") and _port_free(f"tls/[::1]:{port}") and not listening("::1", port)
