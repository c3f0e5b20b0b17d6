"""A router forwards no payload over the wire's limit (net/runtime/session.py PAYLOAD_CAP): real zenoh sessions
on 127.0.0.1, a router opened with the options every `reconswarm router` uses, two clients through it. (A peer
takes none either: tests/system/test_zenoh_peers.py.)"""

from __future__ import annotations

import contextlib
import json
import threading
import time
from pathlib import Path

import zenoh

from reconswarm.net.runtime.session import PAYLOAD_CAP, ZenohOptions, open_session
from reconswarm.scenario.wire_limits import MAX_PAYLOAD_BYTES
from tests.support import free_port, wait_until

SIZES = [0, 1000, 70_000, MAX_PAYLOAD_BYTES, MAX_PAYLOAD_BYTES + 1, 3 * MAX_PAYLOAD_BYTES, 10]


def _through(router: ZenohOptions, endpoint: str) -> list[int]:
    """The payload sizes a subscriber gets when a client publishes SIZES, in order, through `router`."""
    client = ZenohOptions.build([endpoint], None, "client", None)
    r = open_session(router, "router", timeout_s=10.0)
    s = open_session(client, "subscriber", timeout_s=10.0)
    p = open_session(client, "publisher", timeout_s=10.0)
    got: list[int] = []
    try:
        sub = s.declare_subscriber("cap/**", lambda sample: got.append(len(sample.payload.to_bytes())))
        heard = threading.Event()
        probe = s.declare_subscriber("probe", lambda _sample: heard.set())  # (declared after: it arrives after)
        pub = p.declare_publisher("cap/x", congestion_control=zenoh.CongestionControl.BLOCK)
        deadline = time.monotonic() + 10.0  # (a barrier: the subscriptions reached the router once a probe comes)
        while not heard.wait(0.05) and time.monotonic() < deadline:
            p.put("probe", b"")
        probe.undeclare()
        for n in SIZES:
            pub.put(bytes(n))
        with contextlib.suppress(AssertionError):  # (the assertions below say what did not come)
            wait_until(lambda: got and got[-1] == SIZES[-1], 10.0, "the last payload")
        sub.undeclare()
    finally:
        for z in (p, s, r):
            z.close()
    return got


def test_a_router_forwards_payloads_up_to_the_wire_limit_and_none_over_it() -> None:
    ep = f"tcp/127.0.0.1:{free_port()}"
    got = _through(ZenohOptions.build(None, [ep], "router", None), ep)
    assert got == [n for n in SIZES if n <= MAX_PAYLOAD_BYTES]


def test_a_router_config_file_gets_the_cap_unless_it_has_a_filter_of_its_own(tmp_path: Path) -> None:
    ep = f"tcp/127.0.0.1:{free_port()}"
    plain = tmp_path / "router.json5"
    plain.write_text(json.dumps({"mode": "router", "listen": {"endpoints": [ep]},
                                 "scouting": {"multicast": {"enabled": False}}}))
    conf = ZenohOptions.build(None, None, "router", plain).config()
    (cap,) = json.loads(conf.get_json("low_pass_filter"))
    assert {k: v for k, v in cap.items() if v is not None} == PAYLOAD_CAP
    assert _through(ZenohOptions.build(None, None, "router", plain), ep) == [n for n in SIZES if n <= MAX_PAYLOAD_BYTES]
    own = tmp_path / "own.json5"
    mine = {**PAYLOAD_CAP, "id": "mine", "size_limit": 50_000}
    own.write_text(json.dumps({"mode": "router", "listen": {"endpoints": [ep]},
                               "scouting": {"multicast": {"enabled": False}}, "low_pass_filter": [mine]}))
    assert _through(ZenohOptions.build(None, None, "router", own), ep) == [n for n in SIZES if n <= 50_000]


def test_a_client_filters_nothing_itself_a_peer_takes_the_cap() -> None:
    """A client's session still receives (and counts, as rejected) an oversized payload that a router not ours let
    through; a peer, which anyone may link to directly (tests/system/test_zenoh_peers.py), takes none."""
    conf = ZenohOptions.build(["tcp/127.0.0.1:1"], None, "client", None).config()
    assert json.loads(conf.get_json("low_pass_filter")) == []
    conf = ZenohOptions.build(["tcp/127.0.0.1:1"], None, "peer", None).config()
    (cap,) = json.loads(conf.get_json("low_pass_filter"))
    assert {k: v for k, v in cap.items() if v is not None} == PAYLOAD_CAP
