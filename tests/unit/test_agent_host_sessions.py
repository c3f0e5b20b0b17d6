"""An agent host's subscriptions and session (agent/host.py), with a second zenoh session outside it (both on
127.0.0.1): what each subscription takes and with which tag, history for tokens and obstacle sets, nothing of the
host's own; its agents' states wake it at once; ROS 2 mode's own keys; an agent that fails or ends; a closed
host takes nothing more. Each case here was a change of the code that no test noticed (bench/mutation.py)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import zenoh
from zenoh import ext

from agent.host import ALL, AgentHost
from agent.hosted import HostedAgent
from agent.neighbours import Cells
from agent.node import AgentNode
from agent.robot_io import STATES
from agent.ros2_io import AgentRos2, ros2_robot
from reconswarm.net.node import Exit
from reconswarm.net.ros2 import ros2_graph as graph
from reconswarm.net.runtime.inbox import Inbox, Rejections
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import batch_to_wire
from reconswarm.net.wire.hostwire import attachment, state_batches
from reconswarm.net.wire.report import report_from_wire
from tests.support import free_port, wait_subscribed, wait_token, wait_until
from tests.unit.test_agent_host_cases import OTHER, A, B, Item, kinds, make_host, route, state
from tests.unit.test_agent_host_routing import KEYS, PEER, C, S, at_start, beacon, obstacle_set


def host_session() -> Any:
    return zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())


@contextmanager
def two_sessions() -> Iterator[tuple[Any, Any]]:
    """The host's session (listening on a free port) and an outside one connected to it, closed after."""
    port = free_port()
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{port}",), "peer").config())
    out = zenoh.open(ZenohOptions((f"tcp/127.0.0.1:{port}",), (), "peer").config())
    try:
        yield z, out
    finally:
        out.close()
        z.close()


def take_own_tokens(inbox: Inbox, ids: tuple[int, ...]) -> None:
    """Take everything waiting until the hosted agents' own tokens were among it (the host's liveliness subscription
    hears them first), so that what the test puts next is all the inbox holds."""
    early: set[str] = set()

    def heard() -> bool:
        early.update(it[0] for _tag, it in inbox.take(0, 0.0))
        return {KEYS.alive_agent(a) for a in ids} <= early

    wait_until(heard, 10.0, f"the tokens of agents {ids}")


def test_the_hosts_subscriptions_take_remote_samples_tagged_with_history_and_none_of_its_own() -> None:
    with two_sessions() as (z, out):
        h = None
        try:
            # Before the host exists: agent 3's obstacle set in the cache of an advanced publisher, then its token.
            # The token is declared last: once the host's session has it, the publisher's cache (declared before it
            # on the same link) is known there too, so the host's history query finds it.
            home3 = AgentNode(S, 3, 0.0).nb.home
            pub = ext.declare_advanced_publisher(out, KEYS.obstacles(home3, 3), cache=ext.CacheConfig(max_samples=1))
            pub.put(obstacle_set(3, home3)[1])
            token = out.liveliness().declare_token(KEYS.alive_agent(3))
            wait_token(z, KEYS.alive_agent(3))
            h = make_host(z)
            for key in (KEYS.host(1, "state"), KEYS.clock, KEYS.host_beacons(home3, 3)):  # (the host's declarations)
                wait_subscribed(out, key)
            got: list[tuple[Any, Item]] = h.inbox.take(0, 0.0)  # (history: the token and the set)
            out.put(KEYS.host(1, "state"), state_batches(1, [state(1)])[0][0])
            out.put(KEYS.clock, wire.clock_to_wire(wire.Clock(0, 0.0, (1, 2, 3))))
            out.put(KEYS.host_beacons(home3, 3), batch_to_wire(3, [at_start(3)]))
            z.put(KEYS.host_beacons(home3, 4), batch_to_wire(4, [at_start(4)]))  # our own session's: never taken
            z.put(*obstacle_set(4, home3)[:2])
            deadline = time.monotonic() + 10.0
            want = {KEYS.host(1, "state"), KEYS.clock, KEYS.host_beacons(home3, 3), KEYS.alive_agent(3),
                    KEYS.obstacles(home3, 3)}
            while time.monotonic() < deadline and not want <= {it[0] for _t, it in got}:
                got += h.inbox.take(1, 0.5)
            tags: dict[str, set[Any]] = {}
            for tag, it in got:
                tags.setdefault(it[0], set()).add(tag)
            assert tags[KEYS.alive_agent(3)] == {ALL} and tags[KEYS.clock] == {ALL}
            assert tags[KEYS.host(1, "state")] == {STATES}
            assert tags[KEYS.obstacles(home3, 3)] and tags[KEYS.host_beacons(home3, 3)]
            assert all(t[0] == "cell" and t[1] in (None, home3) for t in tags[KEYS.host_beacons(home3, 3)] | tags[
                KEYS.obstacles(home3, 3)])
            assert KEYS.host_beacons(home3, 4) not in tags and KEYS.obstacles(home3, 4) not in tags
            batches = route(h, got)
            assert "Token" in kinds(batches[1]) and "ObstacleSet" in kinds(batches[1]) and "State" in kinds(batches[1])
            assert "State" not in kinds(batches[2]) and "Clock" in kinds(batches[2])
            token.undeclare()
        finally:
            if h is not None:
                h.close()


def test_the_states_of_the_hosted_agents_wake_the_host_at_once_a_peers_beacon_does_not() -> None:
    with two_sessions() as (z, out):
        h = make_host(z)
        try:
            home3 = AgentNode(S, 3, 0.0).nb.home
            for key in (KEYS.host(1, "state"), KEYS.host_beacons(home3, 3)):  # (the declarations reach `out`)
                wait_subscribed(out, key)
            take_own_tokens(h.inbox, (1, 2))
            out.put(KEYS.host_beacons(home3, 3), batch_to_wire(3, [at_start(3)]))  # (not urgent: the take waits it out)
            t0 = time.monotonic()
            assert {it[0] for _tag, it in h.inbox.take(None, 1.0, urgent=1)} == {KEYS.host_beacons(home3, 3)}
            assert time.monotonic() - t0 >= 0.9, "a peer's beacon woke the take as if it were our state"
            got: list[Any] = []
            t0 = time.monotonic()
            taker = threading.Thread(target=lambda: got.extend(h.inbox.take(None, 30.0, urgent=2)))
            taker.start()
            payload, n = state_batches(1, [state(1), state(2)])[0]  # (one message, counted for both states)
            out.put(KEYS.host(1, "state"), payload, attachment=attachment(n))
            taker.join(40.0)
            assert not taker.is_alive()
            assert time.monotonic() - t0 < 15.0, "the states did not wake the take: it waited for its timeout"
            assert [it[0] for _tag, it in got] == [KEYS.host(1, "state")]
        finally:
            h.close()


def test_an_agent_that_fails_stops_listening_and_its_token_goes_one_that_ends_stays() -> None:
    z = host_session()
    host = make_host(z, (1, 2, 3))
    try:
        for a, cell in ((1, A), (2, B), (3, B)):
            host.listen(a, Cells(cell, frozenset({cell})))
        assert alive_tokens(host) == {1, 2, 3}
        hosts = [str(r.ok.key_expr) for r in host.z.liveliness().get(f"{KEYS.prefix}/alive/host/**", timeout=2.0)
                 if r.ok is not None]
        assert hosts == [KEYS.alive_host((1, 2, 3))]  # whom the host speaks for, in its one token
        host.exited(1, Exit(1, "failed"), 0.0)  # it stops; agents 2 and 3 go on
        assert 1 not in host.cells.listening and 1 not in host.cells.by_cell.get(A, set()) and A not in host.cells.subs
        assert alive_tokens(host) == {2, 3}
        host.exited(2, Exit(0, "mission over"), 0.0)  # ended: its token stays until the process closes the host
        assert host.cells.listening[2] == frozenset({B}) and B in host.cells.subs and alive_tokens(host) == {2, 3}
        assert route(host, [(("cell", B), beacon(4, B))]).keys() == {3}
    finally:
        host.close()
        z.close()


def alive_tokens(host: AgentHost) -> set[int]:
    """The agents whose own token the host's session itself sees."""
    got = set()
    for reply in host.z.liveliness().get(KEYS.alive_agent("*"), timeout=2.0):  # type: ignore[arg-type]
        if reply.ok is not None:
            got.add(int(str(reply.ok.key_expr).rsplit("/", 1)[1]))
    return got


def test_an_agent_that_fails_sends_its_final_report_at_once() -> None:
    z = host_session()
    host = make_host(z)
    reports: list[bytes] = []
    sub = host.z.declare_subscriber(KEYS.report_all, lambda s: reports.append(s.payload.to_bytes()))
    try:
        host.listen(1, Cells(A, frozenset({A})))
        host.listen(2, Cells(A, frozenset({A})))
        route(host, [(("cell", A), (KEYS.obstacles(A, 3), b"\x00" * 10**6, "PUT", PEER, 0.0))])
        host.idle(1, 0.0)  # its tally changed: reported (then not again within a second)
        route(host, [(("cell", A), (KEYS.obstacles(A, 3), b"\x00" * 10**6, "PUT", OTHER, 0.0))])
        host.exited(1, Exit(1, "failed"), 0.0)  # final: reported at once, with the second refusal
        wait_until(lambda: len(reports) >= 2, 5.0, "the agent's two reports")
        last = report_from_wire(reports[-1])
        assert len(reports) == 2 and last.rows is not None and sum(r[2] for r in last.rows) == 2
    finally:
        sub.undeclare()
        host.close()
        z.close()


def test_in_ros2_mode_an_agent_takes_its_scan_not_its_state_and_odometry_without_attachment_counts() -> None:
    with two_sessions() as (z, out):
        inbox = Inbox(ordered=True)
        link = HostedAgent(AgentNode(S, 1, 0.0), KEYS, z, Rejections("agent 1"), Gate(S, "agent-1"), ros2_robot(0),
                           None, inbox.callback(("own", 1), urgent=True))
        h = AgentHost(z, KEYS, {1: link}, inbox)
        ros2 = link.robot
        assert isinstance(ros2, AgentRos2)
        try:
            for key in (KEYS.scan(1), ros2.odom_key):  # (the agent's declarations reach `out`)
                wait_subscribed(out, key)
            take_own_tokens(inbox, (1,))
            scan = wire.Scan(1, 0, 0.0, ())
            out.put(KEYS.scan(1), wire.scan_to_wire(scan))
            out.put(KEYS.host(1, "state"), state_batches(1, [state(1)])[0][0])  # (keys mode's: nobody hears it)
            out.put(ros2.odom_key, b"no attachment")
            got: list[Any] = []
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline and (not got or ros2.ros2_node.bad_attachments == 0):
                got += inbox.take(1, 0.3)
            # (one session's puts arrive in order: the odometry came, so a state put before it would have too)
            got += inbox.take(0, 0.0)
            assert [(tag, it[0]) for tag, it in got] == [(("own", 1), KEYS.scan(1))]
            batch = route(h, got)[1]
            assert kinds(batch) == ["Scan", "Invalid"]
        finally:
            h.close()


def test_a_closed_host_takes_nothing_more() -> None:
    with two_sessions() as (z, out):
        h = make_host(z)
        wait_subscribed(out, KEYS.host(1, "state"))
        h.close()  # (its session stays open: a new host on a new session replaces it, this inbox is left)
        for key in (KEYS.host(1, "state"), KEYS.clock):
            wait_subscribed(out, key, matched=False)
        h.inbox.take(0, 0.0)
        marks: list[Any] = []
        mark = z.declare_subscriber("test/mark", marks.append)  # (the same session: the same link, in order)
        wait_subscribed(out, "test/mark")
        out.put(KEYS.host(1, "state"), state_batches(1, [state(1), state(2)])[0][0])
        out.put(KEYS.clock, wire.clock_to_wire(wire.Clock(0, 0.0, (1, 2))))
        out.put("test/mark", b"after the states and the clock")
        wait_until(lambda: marks, 10.0, "the mark put after the states and the clock")
        mark.undeclare()
        assert h.inbox.take(0, 0.0) == []


def test_a_hosted_agents_own_set_back_from_its_cache_is_no_forgery() -> None:
    """An agent that starts listening to a cell the host did not hear yet (after a restart, say: the agents join where
    their robots stand) makes the host declare that cell's subscription, whose history query also reaches the cache
    of a co-hosted agent publishing there: its set comes back stamped with our own session's id. Before, each other
    agent there refused it as an impersonation (4 intrusions in a run with no attacker). Not that set, or from
    another session: refused as before."""
    z = host_session()
    h = make_host(z, (1, 2, 3))
    try:
        h.act(1, Cells(C, None), 0.0)  # agent 1 publishes from cell C, listening to every cell (no command yet)
        mine = wire.ObstacleSet(1, 0, 1, {"diamond": ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0))})
        h.act(1, mine, 0.0)  # (in its publisher's cache)
        assert [kinds(b) for b in route(h, []).values()] == [[], ["ObstacleSet"], ["ObstacleSet"]]  # (handed over)
        h.act(1, Cells(C, frozenset({C})), 0.0)  # its first command: its own cells, C declared now (history query)
        got: list[tuple[Any, Item]] = []
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and not any(it[0] == KEYS.obstacles(C, 1) for _t, it in got):
            got += h.inbox.take(1, 0.3)
        echo = [(tag, it) for tag, it in got if it[0] == KEYS.obstacles(C, 1)]
        assert echo and all(it[3] == h.source for _tag, it in echo)  # (zenoh's reply: our own session's id)
        assert route(h, echo) == {1: [], 2: [], 3: []}  # (agents 2 and 3 listen to every cell: C's too)
        assert all(h.links[a].gate.count == 0 and h.links[a].rej.count == 0 for a in (1, 2, 3))
        # The reply left the cache before agent 1's next put and arrives after it (a restarted host's agents merge
        # their peers' cached sets at once, a put a tick): still its own (before: one impersonation per other agent).
        h.act(1, wire.ObstacleSet(1, 1, 2, {"square": ((1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0))}), 0.0)
        route(h, [])  # (the newer set handed over)
        assert route(h, echo) == {1: [], 2: [], 3: []}
        assert all(h.links[a].gate.count == 0 and h.links[a].rej.count == 0 for a in (1, 2, 3))
        # Another set in agent 1's name stamped with our id, or its very bytes from another session: refused.
        forged = wire.obstacles_to_wire(wire.ObstacleSet(1, 0, 3, {}))
        route(h, [(("cell", C), (KEYS.obstacles(C, 1), forged, "PUT", h.source, 0.0)),
                  (("cell", C), (KEYS.obstacles(C, 1), echo[0][1][1], "PUT", PEER, 0.0))])
        assert h.links[2].gate.count == 2
    finally:
        h.close()
        z.close()


def test_in_ros2_mode_agents_hosted_on_one_session_are_ros2_nodes_with_ids_of_their_own() -> None:
    """rmw_zenoh counts ids within a context (one session), nodes and their entities alike: a ROS 2 tool's graph
    tells two nodes of one session apart by their node ids, and each entity by its id."""
    z = host_session()
    inbox = Inbox(ordered=True)
    zid = str(z.info.zid())
    links = {a: HostedAgent(AgentNode(S, a, 0.0), KEYS, z, Rejections(f"agent {a}"), Gate(S, f"agent-{a}"),
                            ros2_robot(0), zid, inbox.callback(("own", a), urgent=True)) for a in (1, 2)}
    h = AgentHost(z, KEYS, links, inbox)
    try:
        tokens = [graph.parse_token(str(r.ok.key_expr)) for r in z.liveliness().get("@ros2_lv/0/**", timeout=2.0)
                  if r.ok is not None]
        nodes = {e.node_name: e.node_id for e in tokens if e.kind is graph.EntityKind.NODE}
        assert set(nodes) == {"agent_1", "agent_2"} and nodes["agent_1"] != nodes["agent_2"]
        assert all(e.session_id == zid and e.node_id == nodes[e.node_name] for e in tokens)
        ids = [e.entity_id for e in tokens]
        assert len(ids) == 6 and len(set(ids)) == 6  # 2 nodes, each a publisher (cmd_vel) and a subscription (odom)
        assert {e.entity_id for e in tokens if e.kind is graph.EntityKind.NODE} == set(nodes.values())
    finally:
        h.close()
        z.close()
