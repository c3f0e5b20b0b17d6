"""A tick's last step, the law, is the agent's host's (a lone agent's as well): the node returns its Plan and takes
the command back as Law and sends it as it is (the law's rows: test_law_batched; a lone agent's commands against
the brain's: test_agent_node.py `reference`); the node acts on nothing else while its plan is out."""

from __future__ import annotations

from typing import Any

from agent.brain import Plan, commands
from agent.messages import Law
from agent.node import AgentNode
from reconswarm.net.wire import wire
from tests.support import joined
from tests.unit.test_agent_node import A, B, C, S, T, beacon, clock, cmds, state

PTS = ((130.0, 0.0, "diamond"), (131.0, 1.0, "diamond"), (131.0, -1.0, "diamond"))


def script() -> list[list[Any]]:
    """Four ticks with two peers, a scan that makes the set grow, a peer's obstacle set, a peer lost."""
    peer_set = wire.ObstacleSet(B, 1, 1, {"hexagon": ((112.0, 0.0), (113.0, 1.0), (113.0, -1.0))})
    return [[joined(A), joined(B), joined(C)],
            [clock(0), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, PTS)), beacon(B, 0, 104.0, 0.0),
             beacon(C, 0, 109.0, 1.0)],
            [clock(1), state(1, 100.05, 0.0), beacon(B, 1, 104.1, 0.0, rev=1), peer_set, beacon(C, 1, 109.0, 1.1)],
            [clock(2, (A, B)), state(2, 100.1, 0.0), beacon(B, 2, 104.2, 0.0, rev=1)],
            [clock(3, (A, B)), state(3, 100.15, 0.02), beacon(B, 3, 104.3, 0.1, rev=1)]]


def test_the_node_returns_its_plan_and_on_its_law_sends_that_command() -> None:
    hosted, sent = AgentNode(S, A, 0.0, T), []
    for i, batch in enumerate(script()):
        got = hosted.step(batch, 0.01 * i)
        plans = [o for o in got if isinstance(o, Plan)]
        assert not cmds(got)  # never a command before its law
        if not plans:
            continue
        assert len(plans) == 1 and got[-1] is plans[0]  # the plan last
        assert hosted.planning == plans[0].k and hosted.k == plans[0].k - 1
        # (its host: the law of this plan, alone or with others' rows: the same bits, test_law_batched)
        v, w = commands(plans)[0] if i % 2 else (0.125 * i, -0.5)  # (whatever its host says: it is sent)
        rest = hosted.step([Law(plans[0].k, v, w)], 0.01 * i)
        assert hosted.planning == -1 and hosted.k == plans[0].k
        assert cmds(rest) == [wire.Cmd(A, plans[0].k, v, w)] and hosted.last_cmd == cmds(rest)[0]
        sent += cmds(rest)
    assert [c.k for c in sent] == [0, 1, 2, 3] and hosted.brain.rev == 2


def test_while_its_plan_waits_for_the_law_the_node_acts_on_nothing_else() -> None:
    hosted = AgentNode(S, A, 0.0, T)
    for batch in script()[:2]:
        out = hosted.step(batch, 0.0)
    assert isinstance(out[-1], Plan) and hosted.planning == 0
    # (not the runtime's order, which answers at once: the next tick's data while the plan is out)
    assert hosted.step([clock(1), state(1, 100.05, 0.0), beacon(B, 1, 104.1, 0.0), beacon(C, 1, 109.0, 1.1)],
                       0.1) == []
    assert hosted.step([Law(5, *commands([out[-1]])[0])], 0.2) == []  # a law for another tick: not ours
    rest = hosted.step([Law(0, *commands([out[-1]])[0])], 0.3)
    assert [c.k for c in cmds(rest)] == [0] and isinstance(rest[-1], Plan) and rest[-1].k == 1  # then tick 1
