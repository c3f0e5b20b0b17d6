"""An agent host's routing (agent/host.py) on a real zenoh session (alone on 127.0.0.1): a beacon or set goes to
the hosted agents that listen to the cell it was published in, whichever subscription it came through, once; a
set heard before is replayed to an agent that starts listening to its cell; what a co-hosted agent publishes
goes to the others, never back to itself; the host hears only remote samples."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
import zenoh

from agent.beacons import handover_label
from agent.host import AgentHost
from agent.hosted import HostedAgent
from agent.neighbours import Cells
from agent.node import AgentNode
from reconswarm.net.node import Exit, Invalid
from reconswarm.net.runtime.inbox import Inbox, Rejections
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import batch_to_wire
from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.model import load
from tests import support
from tests.support import PAPER, free_port

S = load(PAPER)
KEYS = Keys("host-test")
PEER = "peer-session"
A, B, C = (0, 0), (5, 5), (9, 9)  # cells


@pytest.fixture
def host() -> Iterator[AgentHost]:
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())
    inbox = Inbox(ordered=True)
    zid = str(z.info.zid())
    links = {a: HostedAgent(AgentNode(S, a, 0.0), KEYS, z, Rejections(f"agent {a}"), Gate(S, f"agent-{a}"), None, zid)
             for a in (1, 2)}
    h = AgentHost(z, KEYS, links, inbox)
    try:
        yield h
    finally:
        h.close()
        z.close()


def at_start(aid: int, k: int = 0) -> wire.Beacon:
    """Agent aid's beacon of tick k from its start, with its radius."""
    i = S.agent_index(aid)
    return support.beacon(aid, k, float(S.starts[i][0]), float(S.starts[i][1]), float(S.radii[i]))


def beacon(aid: int, cell: tuple[int, int], source: str = PEER, k: int = 0,
           at: float | None = None) -> tuple[str, bytes, str, str, float]:
    """at_start's beacon as a sample in `cell` from `source` (a batch of one from the host of aid), arrived at `at`
    (None: now)."""
    return (KEYS.host_beacons(cell, aid), batch_to_wire(aid, [at_start(aid, k)]), "PUT", source,
            time.monotonic() if at is None else at)


def obstacle_set(aid: int, cell: tuple[int, int], rev: int = 1) -> tuple[str, bytes, str, str, float]:
    return KEYS.obstacles(cell, aid), wire.obstacles_to_wire(wire.ObstacleSet(aid, 0, rev, {})), "PUT", PEER, 0.0


def ids(batch: list[Any]) -> list[tuple[str, int]]:
    return [(type(m).__name__, m.id) for m in batch if not isinstance(m, Invalid)]


def test_a_beacon_goes_to_those_listening_to_its_cell_once_whichever_subscription(host: AgentHost) -> None:
    assert host.cells.listening == {1: None, 2: None}  # before their first command: every cell
    # (and the cells around their starts, declared now rather than on the mission's first tick)
    cells = host.cells
    assert cells.warm and set(cells.subs) == {None} | cells.warm and cells.locality == zenoh.Locality.REMOTE
    host.listen(1, Cells(A, frozenset({A})))
    assert set(host.cells.subs) == {None, A} | host.cells.warm  # (agent 2 still listens to every cell)
    host.listen(2, Cells(B, frozenset({B})))
    assert set(host.cells.subs) == {A, B}  # the every-cell subscription went once nobody needed it, and the warm
    got = host.route([(("cell", A), beacon(3, A)), (("cell", B), beacon(4, B)), (("cell", B), beacon(5, C))])
    assert ids(got[1]) == [("Beacon", 3)] and ids(got[2]) == [("Beacon", 4)]  # 5's cell: nobody's
    # The same sample through a subscription just replaced (every cell's) and through its cell's: once, to 1.
    item = beacon(6, A)
    got = host.route([(("cell", None), item), (("cell", A), item)])
    assert ids(got[1]) == [("Beacon", 6)] and got[2] == []


def test_a_set_heard_before_is_replayed_to_an_agent_that_starts_listening_to_its_cell(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    got = host.route([(("cell", A), obstacle_set(3, A))])
    assert ids(got[1]) == [("ObstacleSet", 3)] and got[2] == []
    host.listen(2, Cells(B, frozenset({A, B})))  # agent 2 moves towards A: its history is agent 3's set
    got = host.route([])
    assert got[1] == [] and ids(got[2]) == [("ObstacleSet", 3)]
    host.listen(2, Cells(B, frozenset({A, B, C})))  # already heard A: nothing again
    assert host.route([]) == {1: [], 2: []}


def test_what_a_co_hosted_agent_publishes_goes_to_the_others_never_back(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(A, frozenset({A, B})))
    host.act(1, at_start(1), 0.0)  # (handed over as the message itself; on the wire in the round's batch)
    assert host.pending() == {2: 1}  # (the runtime counts it in what agent 2 still needs: nothing need arrive)
    got = host.route([])
    assert got[1] == [] and ids(got[2]) == [("Beacon", 1)] and host.pending() == {}
    # Agent 1's key from another session: agent 1 counts it invalid; agent 2's gate refuses it (agent 1 runs in
    # this process: its beacons never come through the router).
    got = host.route([(("cell", A), beacon(1, A, source=PEER))])
    assert [type(m).__name__ for m in got[1]] == ["Invalid"] and got[2] == []
    assert host.links[1].rej.count == 1 and host.links[2].gate.count == 1


def test_a_beacon_forged_in_a_co_hosted_agents_name_is_refused_even_before_it_spoke(host: AgentHost) -> None:
    """The co-hosted agents' own beacons skip admission (the host hands them over itself), so no pin says who
    speaks for agent 1: the host refuses any beacon or set in its name from another session, at any time."""
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(A, frozenset({A})))
    got = host.route([(("cell", A), beacon(1, A, source=PEER)), (("cell", A), obstacle_set(1, A))])
    assert ids(got[2]) == [] and host.links[2].gate.count == 2
    assert set(host.links[2].gate.tally.rows) == {("impersonation", PEER)}
    # Agent 1 left the process (it failed; agent 2 goes on): a lone agent 1 elsewhere speaks for it now.
    host.exited(1, Exit(1, "failed"), 0.0)
    got = host.route([(("cell", A), beacon(1, A, source=PEER))])
    assert ids(got[2]) == [("Beacon", 1)] and host.links[2].gate.count == 2


def test_a_co_hosted_agents_beacon_reaches_the_others_as_the_message_it_put(host: AgentHost) -> None:
    """Handed over without decoding its bytes again: they decode to that very beacon."""
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(A, frozenset({A})))
    sent = at_start(1)
    host.act(1, sent, 0.0)
    [(tag, (key, _payload, *_rest), message)] = host.loop.local
    assert tag == ("local", 1) and key == handover_label(A, 1) and message is sent
    assert host.out.pending == {A: {1: sent}}  # (on the wire in the round's batch of cell A)
    got = host.route([])
    assert got[1] == [] and len(got[2]) == 1 and got[2][0] is sent and host.loop.local == []


def test_a_co_hosted_agents_set_is_replayed_as_its_own_not_refused(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    out = wire.ObstacleSet(1, 0, 1, {})
    host.act(1, out, 0.0)  # agent 1 publishes its set in cell A: agent 2 does not listen there yet
    assert host.route([]) == {1: [], 2: []}
    host.listen(2, Cells(B, frozenset({A, B})))
    assert host.pending() == {2: 1}  # (replayed to agent 2 alone)
    got = host.route([])
    assert ids(got[2]) == [("ObstacleSet", 1)] and host.links[2].gate.count == 0


def test_a_set_forged_in_a_co_hosted_agents_name_never_stands_in_for_its_genuine_one_at_replay(
        host: AgentHost) -> None:
    """The host keeps the newest set of each agent for an agent that starts listening to its cell later: a refused
    set is never kept, so a forger cannot replace a co-hosted agent's genuine set there (nor a remote one's)."""
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    host.act(1, wire.ObstacleSet(1, 0, 1, {}), 0.0)  # agent 1's genuine set, in cell A
    forged = (KEYS.obstacles(A, 1), wire.obstacles_to_wire(wire.ObstacleSet(1, 0, 9, {})), "PUT", PEER, 0.0)
    got = host.route([(("cell", A), forged)])
    assert [type(m).__name__ for m in got[1]] == ["Invalid"] and got[2] == []  # (agent 1's own key: invalid)
    host.listen(2, Cells(B, frozenset({A, B})))  # agent 2 moves towards A: it gets agent 1's genuine set
    got = host.route([])
    assert [(m.id, m.rev) for m in got[2] if isinstance(m, wire.ObstacleSet)] == [(1, 1)] and len(got[2]) == 1
    assert host.links[2].gate.count == 0
    host.route([(("cell", A), obstacle_set(3, A))])  # agent 3's: kept; then one naming an unknown obstacle: not
    made_up = wire.ObstacleSet(3, 0, 9, {"no-such-obstacle": ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))})
    host.route([(("cell", A), (KEYS.obstacles(A, 3), wire.obstacles_to_wire(made_up), "PUT", PEER, 0.0))])
    assert host.links[1].gate.count == 1
    assert wire.obstacles_from_wire(host.loop.sets[3][1][1], 3).rev == 1


def test_a_remote_sample_is_judged_once_for_every_hosted_agent_it_is_for(host: AgentHost,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Admission is a question about the sample (who sent it, can the robot be there), not about who receives it: a
    host asks its one admission once per sample, and every listening agent takes the admitted message."""
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(A, frozenset({A})))
    asked: list[int] = []
    judge = host.gate.adm.check_beacon

    def counted(b: wire.Beacon, *rest: Any) -> Any:
        asked.append(b.id)
        return judge(b, *rest)

    monkeypatch.setattr(host.gate.adm, "check_beacon", counted)
    got = host.route([(("cell", A), beacon(3, A)), (("cell", A), beacon(4, A))])
    assert asked == [3, 4] and ids(got[1]) == ids(got[2]) == [("Beacon", 3), ("Beacon", 4)]
    assert got[1][0] is got[2][0]  # (one message for both)
    # Refused once, counted by each agent it was for (as each would count it alone).
    got = host.route([(("cell", A), beacon(3, A, source="someone-else", k=1))])
    assert asked == [3, 4, 3] and got == {1: [], 2: []}
    assert host.links[1].gate.count == host.links[2].gate.count == 1


def test_who_speaks_for_a_peer_is_one_answer_for_the_whole_host(host: AgentHost) -> None:
    """A peer pinned to its session by what one hosted agent heard is pinned for the others too: a second session in
    its name is refused by an agent that had not heard the peer yet (it would have believed it, alone)."""
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(B, frozenset({B})))
    assert ids(host.route([(("cell", A), beacon(3, A))])[1]) == [("Beacon", 3)]
    got = host.route([(("cell", B), beacon(3, B, source="someone-else", k=1))])
    assert got == {1: [], 2: []} and host.links[2].gate.count == 1
    assert set(host.links[2].gate.tally.rows) == {("impersonation", "someone-else")}
