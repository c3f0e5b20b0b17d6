"""The law of several agents' plans at once (agent/brain.py `law`, what an agent host computes) equals each
agent's alone bit for bit: the stacked tables (padded with invalid columns), the stacked stall histories
(written back row by row), escape episodes included. Against the in-process engine: test_agent_brain_vs_engine."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.brain import AgentBrain, Peer, commands
from reconswarm.paper.deadlock import StackedStalls, StallState, generator
from reconswarm.paper.planner import Neighbours, ObstacleView
from reconswarm.scenario.model import load
from tests.support import PAPER


def test_tables_stack_with_invalid_columns_that_add_nothing() -> None:
    a = Neighbours(np.array([[[1.0, 2.0], [3.0, 4.0]]]), np.array([[0.5, 0.6]]), np.array([[True, True]]))
    b = Neighbours.empty(1)
    c = Neighbours(np.array([[[5.0, 6.0]], [[7.0, 8.0]]]), np.array([[0.7], [0.8]]), np.array([[True], [False]]))
    got = Neighbours.stack([a, b, c])
    assert got.p.shape == (4, 2, 2) and got.valid.tolist() == [[True, True], [False, False], [True, False],
                                                                 [False, False]]
    assert got.p[0].tolist() == [[1.0, 2.0], [3.0, 4.0]] and got.p[2, 0].tolist() == [5.0, 6.0]
    assert got.r[:, 0].tolist() == [0.5, 0.0, 0.7, 0.8]
    same = Neighbours.stack([a, a])  # (one width: concatenated as they are)
    assert same.p.shape == (2, 2, 2) and same.valid.all()
    v = ObstacleView(np.array([[1.5]]), np.array([[[0.0, 1.0]]]), np.array([[True]]))
    got_v = ObstacleView.stack([ObstacleView.empty(1), v])
    assert got_v.d.tolist() == [[0.0], [1.5]] and got_v.valid.tolist() == [[False], [True]]
    assert got_v.n[1, 0].tolist() == [0.0, 1.0]


def test_stall_states_stack_as_copies_and_unstack_row_by_row() -> None:
    states = [StallState.create(1, 4, [generator(7, a)]) for a in (1, 2, 3)]
    states[1].side[0], states[1].hold[0], states[2].hist_p[3, 0] = -1.0, 5, (9.0, 8.0)
    both = StallState.stack(states)
    assert both.hist_p.shape == (4, 3, 2) and both.side.tolist() == [0.0, -1.0, 0.0]
    assert both.hist_p[3, 2].tolist() == [9.0, 8.0] and both.rngs == [s.rngs[0] for s in states]
    both.side[0], both.hist_e[1, 2] = 1.0, 4.5
    assert states[0].side[0] == 0.0  # (a copy until written back)
    both.unstack(states)
    assert states[0].side.tolist() == [1.0] and states[2].hist_e[1].tolist() == [4.5]
    assert states[1].hold.tolist() == [5] and states[2].hist_p[3, 0].tolist() == [9.0, 8.0]


def test_a_kept_stack_is_taken_again_while_its_rows_are_the_states_own() -> None:
    """StackedStalls: after `give_back`, the same states are not stacked again (the kept stack, current through
    the views: a write through one shows in it); a state whose field was replaced, another state, or another
    list of states is stacked again, and the stack then holds what the states hold."""
    states = [StallState.create(1, 4, [generator(7, a)]) for a in (1, 2, 3)]
    kept = StackedStalls()
    first = kept.take(states)
    first.side[1] = -1.0
    kept.give_back(first, states)
    assert states[1].side.tolist() == [-1.0]
    states[2].hist_p[0, 0] = (4.0, 5.0)  # (in place, through its view)
    again = kept.take(states)
    assert again is first and again.hist_p[0, 2].tolist() == [4.0, 5.0]
    kept.give_back(again, states)
    states[0].hold = np.array([7])  # (replaced, as stall_step on one agent alone does)
    fresh = kept.take(states)
    assert fresh is not first and fresh.hold.tolist() == [7, 0, 0] and fresh.side.tolist() == [0.0, -1.0, 0.0]
    kept.give_back(fresh, states)
    assert kept.take(states) is fresh
    assert kept.take(states[:2]) is not fresh and kept.take(states[:2]).hold.tolist() == [7, 0]
    other = [StallState.create(1, 4, [generator(7, a)]) for a in (1, 2, 3)]
    assert kept.take(other) is not fresh and kept.take(other).side.tolist() == [0.0, 0.0, 0.0]


S = load(PAPER)
ESCAPING = dataclasses.replace(S, planner=dataclasses.replace(S.planner, perturbation_mps=0.4, stall_window_s=0.5))
DIAMOND = S.polygon(0)  # (4, 2) around (300, 0)


@settings(max_examples=15, deadline=None)
@given(spots=st.lists(st.tuples(st.floats(240.0, 360.0), st.floats(-60.0, 60.0)), min_size=2, max_size=6),
       acting=st.lists(st.integers(1, 63), min_size=200, max_size=200), heading=st.floats(-3.2, 3.2))
def test_the_law_of_many_plans_is_each_agents_alone(spots: list[tuple[float, float]], acting: list[int],
                                                    heading: float) -> None:
    """Agents held still beside the diamond (so they stall and escape: W = 10 ticks, episodes of 60, turning
    round once), a different subset of them acting at each tick: the commands (v, ω) of one `commands` call
    (the law, then eq. 3 inverted) equal each agent's own, tick after tick, and so do their stall histories."""
    _compare(spots, acting, heading)


def test_the_same_agents_tick_after_tick_with_one_alone_between() -> None:
    """A host's usual run: the same agents' plans in every call (the kept stack taken again), one agent's alone
    now and then (its rows replaced: stacked again), then the others again; escape episodes included."""
    spots = [(262.0, 8.0), (262.0, -8.0), (300.0, 53.0), (300.0, -53.0), (338.0, 6.0), (338.0, -6.0)]
    _compare(spots, [63] * 70 + [4] * 3 + [63] * 70 + [5] * 20 + [63] * 40, 0.3)


def _compare(spots: list[tuple[float, float]], acting: list[int], heading: float) -> None:
    ids = [int(a) for a in ESCAPING.ids[:len(spots)]]
    together = [AgentBrain(ESCAPING, a) for a in ids]
    alone = copy.deepcopy(together)
    scan = {"diamond": [(float(x), float(y)) for x, y in DIAMOND]}  # (known from the first tick on)
    for k, mask in enumerate(acting):
        who = [i for i in range(len(ids)) if mask >> i & 1] or [0]
        plans, solo = [], []
        for i in who:
            p = np.array(spots[i])
            peers = [Peer(ids[j], *spots[j], 0.5) for j in range(len(ids)) if j != i]
            theta = heading + 0.1 * i
            plans.append(together[i].plan(k, p, scan, peers, [], theta=theta))
            u_i, _grew = alone[i].tick(k, p, scan, peers, [])
            solo.append(alone[i].inputs(u_i, theta))
        assert commands(plans) == solo, k
    for a, b in zip(together, alone, strict=True):
        for f in ("hist_p", "hist_e", "filled", "pert", "hold", "stalls", "side", "turned", "e0", "free_dir"):
            assert getattr(a.stall, f).tolist() == getattr(b.stall, f).tolist(), f
