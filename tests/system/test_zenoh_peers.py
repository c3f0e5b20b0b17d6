"""`run_local.sh --zenoh-mode peer`: the run's processes as zenoh peers, with real sessions on 127.0.0.1. Each
learns the others' endpoints from the router (zenoh's gossip) and connects to them, so their samples go straight
from process to process: once linked, two peers keep hearing each other with the router gone, and each takes no
payload over the wire's limit on its direct links (as the router forwards none)."""

from __future__ import annotations

import queue
from pathlib import Path
from typing import Any

import zenoh

from reconswarm.net.runtime.session import ZenohOptions, open_session
from reconswarm.net.runtime.uplink import neighbours
from reconswarm.scenario.model import load
from reconswarm.scenario.wire_limits import MAX_PAYLOAD_BYTES
from reconswarm_bringup.config import LaunchConfig
from reconswarm_bringup.network import PEER_LISTEN, peer_args, plan_network, zenoh_mode
from tests.support import PAPER, free_port, wait_until

SIZES = [0, 1000, MAX_PAYLOAD_BYTES, MAX_PAYLOAD_BYTES + 1, 3 * MAX_PAYLOAD_BYTES, 10]


def _until(check: Any, timeout_s: float = 10.0) -> bool:
    try:
        wait_until(check, timeout_s, "the check")
    except AssertionError:
        return False
    return True


def test_the_processes_options_for_each_mode(tmp_path: Path) -> None:
    ep = f"tcp/127.0.0.1:{free_port()}"
    s = load(PAPER)
    client = plan_network(LaunchConfig(out=tmp_path, router=ep, zenoh_mode="client"), s, "r1")
    peer = plan_network(LaunchConfig(out=tmp_path, router=ep, zenoh_mode="peer"), s, "r1")
    assert client.zopt("agent", "3") == ([], ["--connect", ep])
    assert peer.zopt("agent", "3") == peer.zopt("simworld") == ([], ["--connect", ep, "--mode", "peer",
                                                                     "--listen", "tcp/127.0.0.1:0"])
    assert peer.watch == client.watch  # (the launcher's own session stays a client)
    assert peer_args("client") == []


def test_auto_is_peer_for_agent_hosts_in_a_few_processes_without_secure_or_two_hosts(tmp_path: Path) -> None:
    def mode(n: int, k: int | str, **kw: Any) -> str:
        return zenoh_mode(LaunchConfig(out=tmp_path, agents_per_process=k, **kw), n)

    # (the paper's 10: one process per agent, 12 processes; K = 2 to 10, 7 to 3 processes with the world and monitor)
    assert [mode(10, k) for k in (1, 2, 3, 5, 10, "auto")] == ["client", "peer", "peer", "peer", "peer", "peer"]
    assert mode(12, 2) == "peer" and mode(14, 2) == "client"  # 6 hosts: 8 processes; 7 hosts: 9
    assert mode(5, 1) == "client"  # (7 processes, but one agent each: no agent host)
    assert mode(144, 8) == "client" and mode(400, "auto") == "peer"  # 18 hosts: 20 processes; 2 hosts of 200
    assert mode(10, 5, secure=True) == mode(10, 5, hosts=2) == "client"
    assert mode(10, 1, zenoh_mode="peer") == "peer" and mode(10, 5, zenoh_mode="client") == "client"


def test_peers_linked_through_the_router_keep_hearing_each_other_without_it() -> None:
    ep = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(ZenohOptions.build(None, [ep], "router", None), "test", timeout_s=10.0)
    a = b = None
    got: queue.SimpleQueue[bytes] = queue.SimpleQueue()
    try:
        a = open_session(ZenohOptions.build([ep], [PEER_LISTEN], "peer", None), "test", timeout_s=10.0)
        b = open_session(ZenohOptions.build([ep], [PEER_LISTEN], "peer", None), "test", timeout_s=10.0)
        b.declare_subscriber("swarm/t/x", lambda smp: got.put(smp.payload.to_bytes()))
        assert _until(lambda: str(b.info.zid()) in {str(z) for z in a.info.peers_zid()})  # linked directly
        assert neighbours(a) == "1 router, 1 peer"
        router.close()
        router = None
        assert _until(lambda: neighbours(a) == "0 routers, 1 peer")
        pub = a.declare_publisher("swarm/t/x", congestion_control=zenoh.CongestionControl.BLOCK)
        assert _until(lambda: (pub.put(b"direct"), not got.empty())[1], 5.0)
        # The wire's limit holds on a direct link too: a peer takes no payload over it (whoever links to it).
        for n in SIZES:
            pub.put(bytes(n))
        sizes: list[int] = []

        def heard_last() -> bool:
            while not got.empty():
                if (x := got.get()) != b"direct":  # (the probes put until the first came may still be coming)
                    sizes.append(len(x))
            return sizes[-1:] == [SIZES[-1]]

        assert _until(heard_last)
        assert sizes == [n for n in SIZES if n <= MAX_PAYLOAD_BYTES]
    finally:
        for z in (a, b, router):
            if z is not None:
                z.close()


def test_a_client_has_the_router_alone() -> None:
    ep = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(ZenohOptions.build(None, [ep], "router", None), "test", timeout_s=10.0)
    c = None
    try:
        c = open_session(ZenohOptions.build([ep], None, "client", None), "test", timeout_s=10.0)
        assert _until(lambda: neighbours(c) == "1 router, 0 peers")
    finally:
        for z in (c, router):
            if z is not None:
                z.close()
