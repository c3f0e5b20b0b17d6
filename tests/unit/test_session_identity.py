"""A session that replaces one the process closed keeps its id (reconswarm/net/runtime/session.py `open_session(zid=)`,
agent/process.py): whoever pinned an agent to the old session's id (admission.Pins) keeps hearing it through the
new one. Real zenoh sessions on 127.0.0.1: a router, a listener and the replaced client."""

from __future__ import annotations

from typing import Any

from reconswarm.net.runtime.inbox import sample_source
from reconswarm.net.runtime.session import ZenohOptions, open_session
from tests.support import free_port, wait_subscribed, wait_until


def _wait(got: list[Any], n: int) -> None:
    wait_until(lambda: len(got) >= n, 5.0, f"{n} samples heard", every_s=0.02)


def test_a_replacing_session_speaks_with_the_closed_ones_id() -> None:
    port = free_port()
    router = open_session(ZenohOptions((), (f"tcp/127.0.0.1:{port}",), "router"), "router", timeout_s=10.0)
    client = ZenohOptions.build([f"tcp/127.0.0.1:{port}"], None, "client", None)
    listener = open_session(client, "listener", timeout_s=10.0)
    got: list[str] = []
    sub = listener.declare_subscriber("id/**", lambda sample: got.append(sample_source(sample)))
    try:
        first = open_session(client, "agent", timeout_s=10.0)
        zid = str(first.info.zid())
        wait_subscribed(first, "id/a")
        first.put("id/a", b"1")
        _wait(got, 1)
        first.close()
        second = open_session(client, "agent", timeout_s=10.0, zid=zid)
        try:
            assert str(second.info.zid()) == zid
            wait_subscribed(second, "id/a")
            second.put("id/a", b"2")
            _wait(got, 2)
        finally:
            second.close()
        fresh = open_session(client, "agent", timeout_s=10.0)
        assert str(fresh.info.zid()) != zid
        fresh.close()
        assert got == [zid, zid]
    finally:
        sub.undeclare()
        listener.close()
        router.close()
