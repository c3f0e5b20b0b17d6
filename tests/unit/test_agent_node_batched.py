"""A hosted agent's node (`batched`): a tick's last step, the law, is its host's. The node returns its Plan and
takes the command back as Law; everything it does is what the same node alone does, in the same order."""

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


def test_a_batched_node_returns_its_plan_and_on_its_law_does_what_it_does_alone() -> None:
    alone, hosted = AgentNode(S, A, 0.0, T), AgentNode(S, A, 0.0, T, batched=True)
    for i, batch in enumerate(script()):
        now = 0.01 * i
        want = alone.step(batch, now)
        got = hosted.step(batch, now)
        plans = [o for o in got if isinstance(o, Plan)]
        if not cmds(want):
            assert got == want and not plans
            continue
        assert len(plans) == 1 and got[-1] is plans[0] and not cmds(got)  # the plan last, no command yet
        assert hosted.planning == plans[0].k and hosted.k == plans[0].k - 1
        # (its host: the law of this plan, alone or with others' rows: the same bits, test_law_batched)
        rest = hosted.step([Law(plans[0].k, *commands(plans)[0])], now)
        assert [*got[:-1], *rest] == want  # the same outputs, in the same order: set, command, cells
        assert hosted.planning == -1 and hosted.k == alone.k
    assert alone.k == 3 and alone.brain.rev == hosted.brain.rev == 2
    assert hosted.brain.stall.hist_p.tolist() == alone.brain.stall.hist_p.tolist()


def test_while_its_plan_waits_for_the_law_the_node_acts_on_nothing_else() -> None:
    hosted = AgentNode(S, A, 0.0, T, batched=True)
    for batch in script()[:2]:
        out = hosted.step(batch, 0.0)
    assert isinstance(out[-1], Plan) and hosted.planning == 0
    # (not the runtime's order, which answers at once: the next tick's data while the plan is out)
    assert hosted.step([clock(1), state(1, 100.05, 0.0), beacon(B, 1, 104.1, 0.0), beacon(C, 1, 109.0, 1.1)],
                       0.1) == []
    assert hosted.step([Law(5, *commands([out[-1]])[0])], 0.2) == []  # a law for another tick: not ours
    rest = hosted.step([Law(0, *commands([out[-1]])[0])], 0.3)
    assert [c.k for c in cmds(rest)] == [0] and isinstance(rest[-1], Plan) and rest[-1].k == 1  # then tick 1
