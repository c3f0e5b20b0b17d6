"""Our own session losing its router is no agent's loss: the membership rule (Membership.link, confirm_s)
and the link as a real client session sees it (Uplink, a real router process killed and started again)."""

from __future__ import annotations

import signal
import subprocess
import sys
from dataclasses import replace

import pytest
import zenoh

from reconswarm.net.node import RouterReach
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.runtime.uplink import LinkChange, Uplink
from reconswarm.net.trust.membership import Membership, Policy
from reconswarm.net.wire.wire import ClockMode
from tests.support import ROOT, free_port, wait_until
from tests.unit.test_world_node import IDS, S, T, advance, commands, ended, started, ticks, tokens


def _members(relink_settle_s: float = T.relink_settle_s) -> Membership:
    """Fresh 2 s / 2 s, grace 10 s / 5 s, a token's end confirmed 0.3 s later."""
    m = Membership(replace(Policy.world(T), relink_settle_s=relink_settle_s))
    for a in (1, 2, 3):
        m.token(a, True, 0.0, 0.0)
    m.start(1.0, 0.0)
    for a in (1, 2, 3):
        m.data(a, 10.0, 20.0)
    return m


def test_a_token_that_goes_is_gone_once_confirmed() -> None:
    m = _members()
    m.token(2, False, 10.5, 21.0)
    assert m.alive(2, 10.7, 21.4)  # not yet confirmed
    assert not m.alive(2, 10.8, 21.6)  # 0.3 s later: gone
    m.token(3, False, 10.9, 21.8)
    m.token(3, True, 11.0, 22.0)  # back within confirm_s: never gone
    assert m.alive(3, 11.5, 23.0)


def test_while_our_router_is_gone_nobody_is_lost() -> None:
    """The router dies at wall 10.5: every token goes (before our session sees its link go, as measured),
    nobody's data comes for 20 s while a realtime clock runs on; the router is back at 30.5 and the tokens
    come back one by one, agent 3's never (it died meanwhile)."""
    m = _members()
    for a in (1, 2, 3):
        m.token(a, False, 10.5, 21.0)
    m.link(False, 10.6, 21.2)  # within confirm_s of the tokens going
    for w in (11.0, 15.0, 30.0):
        assert m.alive_ids(w, 2 * w) == [1, 2, 3]  # no data for 20 s, tokens gone: nobody judged
    m.link(True, 30.5, 61.0)  # tokens have 10 s to come back
    m.token(1, True, 31.0, 62.0)
    m.token(2, True, 34.0, 68.0)  # a client retries its router at most every 4 s
    assert m.alive_ids(35.0, 70.0) == [1, 2, 3]  # settling: 3 still has time to come back
    assert m.alive_ids(39.0, 78.0) == [1, 2, 3]  # no data yet since the link came back: within the grace
    m.data(1, 40.0, 80.0)
    m.data(2, 40.2, 80.4)
    assert m.alive_ids(40.5, 81.0) == [1, 2]  # settled: 3 is gone; 1 and 2 speak again
    assert m.alive_ids(45.0, 90.0) == []  # their data stopped again, past fresh_s and fresh_sim_s: gone


def test_after_the_link_is_back_a_token_that_goes_is_judged_again() -> None:
    m = _members(relink_settle_s=1.0)
    m.link(False, 10.6, 21.2)
    m.link(True, 12.0, 24.0)
    m.data(2, 13.5, 27.0)
    m.token(2, False, 14.0, 28.0)
    assert not m.alive(2, 14.3, 28.6)


def _router(endpoint: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "reconswarm_bringup.cli", "router", "--listen", endpoint],
                            stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, cwd=ROOT)


def _wait(uplink: Uplink, timeout_s: float) -> LinkChange | None:
    try:
        return wait_until(uplink.poll, timeout_s, "a change of the router link")
    except AssertionError:
        return None


def test_uplink_sees_its_router_killed_and_a_new_one_on_the_same_endpoint() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = _router(endpoint)
    session = None
    try:
        session = zenoh.open(ZenohOptions.build([endpoint], None, "client", None).config())
        uplink = Uplink(session, "test")
        assert uplink.followed and len(uplink.routers) == 1 and uplink.poll() is None
        first = set(uplink.routers)
        router.send_signal(signal.SIGKILL)
        router.wait()
        assert _wait(uplink, 10.0) is LinkChange.DOWN and uplink.down
        router = _router(endpoint)
        assert _wait(uplink, 30.0) is LinkChange.UP and not uplink.down
        assert uplink.routers and set(uplink.routers) != first  # the client reconnected by itself, to a new router
    finally:
        if session is not None:
            session.close()
        router.kill()
        router.wait()


def test_a_peer_session_is_not_followed() -> None:
    conf = ZenohOptions.build([], [f"tcp/127.0.0.1:{free_port()}"], "peer", None).config()
    session = zenoh.open(conf)
    try:
        uplink = Uplink(session, "test")
        assert not uplink.followed and uplink.poll() is None
    finally:
        session.close()


class _Routers:
    """A session object whose routers the test sets (only `info.routers_zid`, what the uplink reads), counting
    the reads."""

    def __init__(self) -> None:
        self.ids, self.reads = ["r1"], 0
        self.info = self

    def routers_zid(self) -> list[str]:
        self.reads += 1
        return list(self.ids)


def test_the_uplink_reads_the_routers_at_most_every_poll_s(monkeypatch: pytest.MonkeyPatch) -> None:
    """Polled on every turn of a loop, the uplink reads the routers once per POLL_S: a change shows at the first
    poll after that, not before; then the next read waits POLL_S again. (POLL_S set long while a read must not
    happen, 0 once it is due: nothing here depends on how fast the machine runs.)"""
    monkeypatch.setattr(Uplink, "POLL_S", 60.0)
    session = _Routers()
    uplink = Uplink(session, "test")
    assert uplink.followed and session.reads == 1
    session.ids = []
    assert uplink.poll() is None and session.reads == 1  # (read a moment ago: not again yet)
    monkeypatch.setattr(Uplink, "POLL_S", 0.0)
    assert uplink.poll() is LinkChange.DOWN and uplink.down and session.reads == 2
    monkeypatch.setattr(Uplink, "POLL_S", 60.0)
    session.ids = ["r2"]
    assert uplink.poll() is None and session.reads == 2
    monkeypatch.setattr(Uplink, "POLL_S", 0.0)
    assert uplink.poll() is LinkChange.UP and not uplink.down and uplink.routers == frozenset({"r2"})


def test_the_world_holds_while_its_own_link_is_gone_and_steps_nobody_uncommanded() -> None:
    """Lockstep: the router dies while tick 3 waits for commands (two are in), taking every token with it a
    moment before our session sees its link go. The world neither times the step out nor holds a robot nor
    loses anybody: it waits for its link, publishes tick 3 again once back, and goes on."""
    node = started()
    now = 0.0
    for k in range(3):
        node.step([], now)
        node.step(commands(k, (1.0, 0.0), now), now)
    node.step([], now)  # tick 3 published
    node.step([*commands(3, (1.0, 0.0), now, skip=tuple(IDS[2:])), *tokens(up=False)], now)
    out = advance(node, now, now + 4 * T.step_timeout_s, every_s=0.1, inputs=[RouterReach(False)])  # 12 s
    now += 4 * T.step_timeout_s
    assert node.k == 3 and not ended(out) and node.strikes == {} and node.uncommanded_k == -1
    assert node.alive == set(IDS)
    again = node.step([RouterReach(True), *tokens()], now)
    assert [t.clock.k for t in ticks(again)] == [3]  # tick 3 again, for the agents whose state went nowhere
    node.step(commands(3, (1.0, 0.0), now, skip=tuple(IDS[:2])), now)  # (the first two were kept)
    assert node.k == 4 and node.uncommanded_k == -1


def test_a_realtime_world_resumes_its_schedule_after_the_link_and_ends_if_it_never_comes_back() -> None:
    node = started(ClockMode.REALTIME)
    advance(node, 0.0, 1.0, every_s=0.01)
    k = node.k
    assert k > 0
    advance(node, 1.0, 11.0, every_s=0.01, inputs=[RouterReach(False)])
    assert node.k == k  # held: no tick while nobody is reachable
    advance(node, 11.0, 11.5, every_s=0.01, inputs=[RouterReach(True)])
    period = S.meta.dt_s / 10.0
    assert node.k - k <= round(0.5 / period) + 2  # the schedule moved on by the hold: no burst of ticks
    end = advance(node, 11.5, 11.5 + T.no_agents_grace_s + 1.0, every_s=0.5, inputs=[RouterReach(False)])
    assert ended(end) == "no agents"
