"""An agent host's routing (agent/host.py) at the edges tests/unit/test_agent_host_routing.py leaves, on a real
zenoh session (alone on 127.0.0.1): an agent's own samples, the clock and the tokens for every running agent, the
obstacle sets' size cap, what the once-a-round filter may and may not merge, what is kept and replayed, what the
host does with its nodes' outputs and plans, what a refusal logs. Each case here was a change of the code that no
test noticed (bench/mutation.py agent/host.py)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest
import zenoh

from agent.brain import Plan, commands
from agent.host import ALL, AgentHost
from agent.hosted import HostedAgent
from agent.messages import Law, Reconnect
from agent.neighbours import Cells
from agent.node import AgentNode
from agent.robot_io import STATES
from reconswarm.net.node import Exit, Role, Token
from reconswarm.net.runtime.inbox import Inbox, Rejections
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import batch_to_wire
from reconswarm.net.wire.hostwire import cmd_batch_from_wire, state_batches
from tests.support import free_port
from tests.unit.test_agent_host_routing import KEYS, PEER, S, beacon, obstacle_set
from tests.unit.test_agent_node import A as NODE_AGENT
from tests.unit.test_agent_node import S as NODE_S
from tests.unit.test_agent_node import T as NODE_T
from tests.unit.test_agent_node_law import script

OTHER = "other-session"
A, B = (0, 0), (5, 5)  # cells
Item = tuple[str, bytes, str, str, float]


def make_host(z: Any, ids: tuple[int, ...] = (1, 2)) -> AgentHost:
    inbox, zid = Inbox(ordered=True), str(z.info.zid())
    links = {a: HostedAgent(AgentNode(S, a, 0.0), KEYS, z, Rejections(f"agent {a}"), Gate(S, f"agent-{a}"), None, zid)
             for a in ids}
    return AgentHost(z, KEYS, links, inbox)


@contextmanager
def lone_host() -> Iterator[AgentHost]:
    """Agents 1 and 2 hosted on a session of their own (a peer that listens, linked to nobody)."""
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())
    h = make_host(z)
    try:
        yield h
    finally:
        h.close()
        z.close()


@pytest.fixture
def host() -> Iterator[AgentHost]:
    with lone_host() as h:
        yield h


def state(aid: int, k: int = 0) -> wire.State:
    x, y = (float(v) for v in S.starts[S.agent_index(aid)])
    return wire.State(aid, k, 0.05 * k, x, y, 0.0, x, y)


def route(host: AgentHost, items: list[tuple[Any, Item]]) -> dict[int, list[Any]]:
    """Each hosted agent's batch (its inputs, as the tests read them)."""
    return dict(host.route(items))


def kinds(batch: list[Any]) -> list[str]:
    return [type(m).__name__ for m in batch]


def states(*sts: wire.State, host: int = 1) -> Item:
    """The world's message of a host's states (its one message: no scan is large)."""
    ((payload, _n),) = state_batches(host, list(sts))
    return (KEYS.host(host, "state"), payload, "PUT", "world", 0.0)


def test_the_hosts_state_batch_is_taken_apart_once_each_state_to_its_agent_a_malformed_one_counts_once(
        host: AgentHost) -> None:
    got = route(host, [(STATES, states(state(1), state(2)))])
    assert kinds(got[1]) == ["State"] and got[1][0].id == 1 and kinds(got[2]) == ["State"] and got[2][0].id == 2
    got = route(host, [(STATES, (KEYS.host(1, "state"), b"\xc1 not msgpack", "PUT", "world", 0.0))])
    assert kinds(got[1]) == ["Invalid"] and got[2] == [] and host.links[1].rej.count == 1
    assert host.links[2].rej.count == 0
    host.exited(1, Exit(1, "failed"), 0.0)
    got = route(host, [(STATES, states(state(1), state(2)))])
    assert list(got) == [2] and kinds(got[2]) == ["State"]  # (agent 1's state: nobody's now)


def test_a_state_batch_naming_an_agent_we_do_not_host_is_one_intrusion_and_that_row_not_believed(
        host: AgentHost) -> None:
    got = route(host, [(STATES, states(state(1), state(3)))])
    assert kinds(got[1]) == ["State"] and got[2] == []
    assert host.links[1].gate.tally.total == 1 and host.links[2].gate.tally.total == 0
    assert set(host.links[1].gate.tally.rows) == {("impersonation", "world")}


def test_the_clock_and_the_tokens_go_to_every_running_agent(host: AgentHost) -> None:
    clock = (KEYS.clock, wire.clock_to_wire(wire.Clock(0, 0.0, (1, 2, 3))), "PUT", "world", 0.0)
    gone = (KEYS.alive_agent(3), b"", "DELETE", PEER, 0.0)
    got = route(host, [(ALL, clock), (ALL, gone)])
    for a in (1, 2):
        assert kinds(got[a]) == ["Clock", "Token"] and got[a][1] == Token(Role.AGENT, False, 3)
    # The same live agents in the next clock: one tuple for every agent (not a copy per clock); new ones: new.
    first = got[1][0].alive
    again = (KEYS.clock, wire.clock_to_wire(wire.Clock(1, 0.05, (1, 2, 3))), "PUT", "world", 0.0)
    got = route(host, [(ALL, again)])
    assert got[1][0].alive is first and got[2][0].alive is first
    other = (KEYS.clock, wire.clock_to_wire(wire.Clock(2, 0.1, (1, 2))), "PUT", "world", 0.0)
    got = route(host, [(ALL, other)])
    assert got[1][0].alive == (1, 2)
    host.exited(1, Exit(1, "failed"), 0.0)
    assert kinds(route(host, [(ALL, clock)])[2]) == ["Clock"] and 1 not in route(host, [(ALL, clock)])


def test_an_obstacle_set_larger_than_any_the_run_can_send_is_refused_by_each_listener_undecoded(
        host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(A, frozenset({A})))
    cap = host.links[1].gate.adm.max_set_bytes
    big = (KEYS.obstacles(A, 3), b"\x00" * (cap + 1), "PUT", PEER, 0.0)
    assert route(host, [(("cell", A), big)]) == {1: [], 2: []}
    assert host.links[1].gate.count == 1 and host.links[2].gate.count == 1
    assert set(host.links[1].gate.tally.rows) == {("oversize", PEER)} and host.links[1].rej.count == 0
    # A beacon that large is no set: decoded (malformed here), counted as invalid, no intrusion.
    huge = (KEYS.host_beacons(A, 3), b"\x00" * (cap + 1), "PUT", PEER, 0.0)
    got = route(host, [(("cell", A), huge)])
    assert kinds(got[1]) == ["Invalid"] and host.links[1].gate.count == 1 and host.links[1].rej.count == 1


def test_the_once_a_round_filter_merges_only_one_sample_through_two_subscriptions(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    genuine = beacon(3, A, at=1.0)
    replayed = (genuine[0], genuine[1], "PUT", OTHER, 1.0)  # the same bytes at the same time, another session
    later = beacon(3, A, k=1, at=1.0)  # the same key and source, the next tick's bytes
    moved = (KEYS.host_beacons(B, 3), genuine[1], "PUT", PEER, 1.0)  # the same bytes under another cell's key
    got = route(host, [(("cell", A), genuine), (("cell", None), genuine), (("cell", A), replayed),
                      (("cell", A), later), (("cell", B), moved)])
    assert [(m.id, m.k) for m in got[1]] == [(3, 0), (3, 1)]  # the replay refused by agent 1's admission, counted
    assert host.links[1].gate.count == 1 and {r[0] for r in host.links[1].gate.tally.rows} == {"impersonation"}
    assert [(m.id, m.k) for m in got[2]] == [(3, 0)]


def test_only_sets_of_the_scenarios_agents_in_a_cell_are_kept_for_replay(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    stranger = obstacle_set(99, A)
    bad_key = (f"{KEYS.prefix}/cell/x_y/agent/3/obstacles", obstacle_set(3, A)[1], "PUT", PEER, 0.0)
    route(host, [(("cell", A), stranger), (("cell", A), bad_key)])
    assert host.loop.sets == {}
    assert host.links[1].gate.count == 1  # (agent 99 is no agent of the scenario: refused)


def test_what_the_host_does_with_its_nodes_outputs(host: AgentHost) -> None:
    assert host.act(1, Reconnect(), 0.0) is True  # a new session for the process
    assert host.act(1, Cells(A, frozenset({A, B})), 0.0) is False and host.cells.listening[1] == frozenset({A, B})
    assert host.act(1, Cells(A, frozenset({A})), 0.0) is False and host.cells.listening[1] == frozenset({A})
    host.listen(2, Cells(B, frozenset({A})))
    assert host.act(1, wire.Beacon(1, 0, 0.0, 1.0, 1.0, 2.0), 0.0) is False
    got = route(host, [])
    assert kinds(got[2]) == ["Beacon"] and got[1] == []


def test_a_forgery_in_a_co_hosted_agents_name_is_refused_by_every_other_agent_and_logged_with_its_key(
        caplog: pytest.LogCaptureFixture) -> None:
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())
    host = make_host(z, (1, 2, 3))
    try:
        for a in (1, 2, 3):
            host.listen(a, Cells(A, frozenset({A})))
        forged = beacon(2, A, source=PEER)
        with caplog.at_level("WARNING"):
            got = route(host, [(("cell", A), forged)])
        assert got[1] == [] and got[3] == [] and kinds(got[2]) == ["Invalid"]  # (its own key: invalid for agent 2)
        assert host.links[1].gate.count == 1 and host.links[3].gate.count == 1 and host.links[2].rej.count == 1
        said = [r.getMessage() for r in caplog.records if "impersonation" in r.getMessage()]
        assert said and all(forged[0] in s and "agent 2 is hosted in our process" in s for s in said)
    finally:
        host.close()
        z.close()


def test_a_refusal_is_logged_with_the_key_it_came_on(host: AgentHost, caplog: pytest.LogCaptureFixture) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    cap = host.links[1].gate.adm.max_set_bytes
    big = (KEYS.obstacles(A, 3), b"\x00" * (cap + 1), "PUT", PEER, 0.0)
    odd = beacon(3, A, source=PEER)
    liar = (odd[0], batch_to_wire(3, [wire.Beacon(3, 0, 0.0, 1e6, 1e6, float(S.radii[S.agent_index(3)]))]),
            "PUT", OTHER, 0.0)
    with caplog.at_level("WARNING"):
        route(host, [(("cell", A), big), (("cell", A), liar)])
    said = [r.getMessage() for r in caplog.records]
    assert any("oversize" in s and big[0] in s for s in said) and any("position" in s and liar[0] in s for s in said)


def test_a_key_without_a_valid_cell_counts_as_invalid_for_those_its_subscription_serves(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    six_parts = f"{KEYS.prefix}/cell/0_0/host/3/beacons/more"
    no_cell = f"{KEYS.prefix}/cell/x_y/host/3/beacons"
    payload = beacon(3, A)[1]
    got = route(host, [(("cell", B), (six_parts, payload, "PUT", PEER, 0.0)),
                      (("cell", None), (no_cell, payload, "PUT", PEER, 0.0)),
                      (("cell", A), beacon(3, A))])
    assert kinds(got[2]) == ["Invalid"] and host.links[2].rej.count == 1  # (cell B's subscription: agent 2's)
    assert kinds(got[1]) == ["Beacon"] and host.links[1].rej.count == 0  # (nobody listens to every cell now)


def test_each_agent_that_starts_listening_to_a_cell_gets_that_cells_sets_and_no_others(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    route(host, [(("cell", A), obstacle_set(3, A)), (("cell", B), obstacle_set(4, B))])
    host.listen(1, Cells(A, frozenset({A, B})))  # both move in the same round: each its own replay
    host.listen(2, Cells(B, frozenset({A, B})))
    got = route(host, [])
    assert [m.id for m in got[1]] == [4] and [m.id for m in got[2]] == [3]


def test_the_plans_of_a_round_are_answered_together_by_tick_then_forgotten(host: AgentHost) -> None:
    def plans_of(ticks: int) -> list[Plan]:
        node, out = AgentNode(NODE_S, NODE_AGENT, 0.0, NODE_T), []  # (any brain's plans)
        for batch in script()[:ticks]:
            out = node.step(batch, 0.0)
        return [o for o in out if isinstance(o, Plan)]

    (p1,), (p2,) = plans_of(2), plans_of(2)
    assert host.act(1, p1, 0.0) is False and host.act(2, p2, 0.0) is False  # (no new session: the law comes)
    want = commands([p1])[0]
    assert answers(host) == {1: [Law(p1.k, *want)], 2: [Law(p2.k, *want)]}
    assert answers(host) == {}


def test_each_agent_gets_the_law_of_its_own_plan_when_the_plans_differ() -> None:
    """Three hosted agents with three different plans of one tick: each law goes to the agent whose plan it is."""
    node, out = AgentNode(NODE_S, NODE_AGENT, 0.0, NODE_T), []
    for batch in script()[:2]:
        out = node.step(batch, 0.0)
    (p,) = (o for o in out if isinstance(o, Plan))
    mine = {1: p, 2: p._replace(pos=p.pos + np.array([[3.0, -2.0]]), theta=p.theta + 0.5),
            3: p._replace(pos=p.pos + np.array([[-4.0, 1.0]]), theta=p.theta - 0.8)}
    want = {aid: [Law(p.k, *commands([plan])[0])] for aid, plan in mine.items()}
    assert len({commands([plan])[0] for plan in mine.values()}) == 3  # (three different laws)
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())
    host = make_host(z, (1, 2, 3))
    try:
        for aid, plan in mine.items():
            assert host.act(aid, plan, 0.0) is False
        assert answers(host) == want
    finally:
        host.close()
        z.close()


def answers(host: AgentHost) -> dict[int, list[Any]]:
    return dict(host.answers(0.0))


def test_our_state_from_a_session_other_than_the_worlds_is_refused(host: AgentHost) -> None:
    forged = states(state(1, 1), state(2, 1))
    got = route(host, [(STATES, states(state(1), state(2))), (STATES, (*forged[:3], OTHER, 0.0))])
    assert [m.k for m in got[1]] == [0] and [m.k for m in got[2]] == [0]
    assert set(host.links[1].gate.tally.rows) == {("not_from_world", OTHER)} and host.links[1].gate.tally.total == 1


def test_the_commands_of_a_round_go_out_in_one_message_once_the_round_is_over(host: AgentHost) -> None:
    assert host.robots is not None
    sent: list[tuple[bytes, Any]] = []
    host.robots.pub = type("Pub", (), {"put": lambda _self, p, **kw: sent.append((p, kw)),
                                       "undeclare": lambda _self: None})()
    host.act(1, wire.Cmd(1, 0, 1.0, 0.0), 0.0)
    host.act(2, wire.Cmd(2, 0, 2.0, 0.5), 0.0)
    host.act(1, wire.Cmd(1, 0, 1.0, 0.0), 0.0)  # (sent again in the round: its tick seen twice; one row)
    assert sent == []  # (not before the round is over)
    assert answers(host) == {} and len(sent) == 1
    assert cmd_batch_from_wire(sent[0][0], 1).cmds == (wire.Cmd(2, 0, 2.0, 0.5), wire.Cmd(1, 0, 1.0, 0.0))
    assert answers(host) == {} and len(sent) == 1  # (nothing new: nothing put)


def test_what_a_hosted_agent_will_find_in_its_next_batch_is_counted_per_agent(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    route(host, [(("cell", A), obstacle_set(a, A)) for a in (3, 4)])
    host.listen(2, Cells(B, frozenset({A, B})))  # two sets replayed to agent 2
    assert host.pending() == {2: 2}
    route(host, [])
    host.act(1, wire.Beacon(1, 0, 0.0, 1.0, 1.0, 2.0), 0.0)
    host.act(1, wire.Beacon(1, 1, 0.05, 1.0, 1.0, 2.0), 0.0)
    assert host.pending() == {2: 2}
