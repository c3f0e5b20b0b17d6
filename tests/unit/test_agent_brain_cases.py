"""An agent's plan and law (agent/brain.py), case by case: the obstacle table a plan hands the law (lost robots
merged with a known hull: one column per merged obstacle), and the law of several plans (an agent host's)
equal to each agent's alone where the plans differ in shape: different head offsets, an agent that knows
nothing beside one that knows a hull, a lone lost robot. Against the in-process engine, tick by tick:
test_agent_brain_vs_engine.py (the paper, stall escapes, the virtual leader)."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from agent.brain import AgentBrain, Peer, commands
from reconswarm.geometry.plane import Edges
from reconswarm.paper.blocked import blocked_hulls, pass_gap_m
from reconswarm.paper.knowledge import obstacle_view
from reconswarm.scenario.model import PlannerKind, load
from tests.support import PAPER

S = load(PAPER)
DIAMOND = S.polygon(0)  # (4, 2) around (300, 0)
SCAN = {"diamond": [(float(x), float(y)) for x, y in DIAMOND]}
# One agent's tick: k, p, scan, peers, lost robots, heading θ.
Args = tuple[int, np.ndarray, dict[str, list[tuple[float, float]]], list[Peer], list[Peer], float]


def swarm(b: AgentBrain) -> list[dict[str, np.ndarray]] | None:
    """The virtual leader's sets of the swarm (one peer that knows the diamond); None for the paper's planner."""
    return [{"diamond": DIAMOND}] if b.leader is not None else None


def each_alone(brains: list[AgentBrain], args: list[Args]) -> list[tuple[float, float]]:
    """Each agent's own command (v, ω), computed on a copy of its brain."""
    out = []
    for b, (k, p, scan, peers, lost, theta) in zip(copy.deepcopy(brains), args, strict=True):
        u, _ = b.tick(k, p, scan, peers, [], swarm(b), lost)
        out.append(b.inputs(u, theta))
    return out


def together(brains: list[AgentBrain], args: list[Args]) -> list[tuple[float, float]]:
    return commands([b.plan(k, p, scan, peers, [], swarm(b), lost, theta)
                     for b, (k, p, scan, peers, lost, theta) in zip(brains, args, strict=True)])


def test_lost_robots_beside_a_known_hull_are_one_obstacle_column_in_the_plan():
    """Robot 3 lost by the diamond's lower vertex: the plan's table has one column, the merged obstacle's signed
    distance and normal (blocked_hulls), not one per edge of it."""
    r = S.agents[S.agent_index(6)].radius_m
    dead = Peer(3, 283.8665541598868, -46.63689867943773, S.agents[S.agent_index(3)].radius_m)
    brain = AgentBrain(S, 6)
    p = np.array([271.2848947074212, -36.45158833842402])
    plan = brain.plan(0, p, SCAN, [], [], None, [dead])
    hulls, absorbed = blocked_hulls([brain.known.hulls["diamond"]],
                                    np.array([[dead.px, dead.py, dead.radius]]), pass_gap_m(r, S.planner.d_max_m))
    assert len(hulls) == 1 and absorbed.tolist() == [True]
    want = obstacle_view(p.reshape(1, 2), 1, 1, np.zeros(1, dtype=np.int64), np.arange(1), Edges.of(hulls))
    assert plan.ob.d.shape == (1, 1) and plan.ob.valid.tolist() == [[True]]
    assert plan.ob.d.tolist() == want.d.tolist() and plan.ob.n.tolist() == want.n.tolist()
    assert plan.nb.p.shape[1] == 0  # (robot 3 is in the obstacle, not a neighbour)


def test_commands_of_agents_with_different_head_offsets_are_each_agents_alone():
    agents = tuple(dataclasses.replace(a, head_offset_m=0.3 + 0.2 * i) for i, a in enumerate(S.agents))
    s = dataclasses.replace(S, agents=agents)
    for n in (2, 3):
        brains = [AgentBrain(s, a.id) for a in agents[:n]]
        args: list[Args] = [(0, np.array([100.0 + 30 * i, 5.0 * i]), {}, [], [], 0.4 + 0.5 * i) for i in range(n)]
        want = each_alone(brains, args)
        assert len(set(want)) == n
        assert together(brains, args) == want


def test_the_virtual_leaders_plans_stack_with_its_velocity_fed_forward():
    """The benchmark's law for several agents at once: each row with its own copy of the leader, whose velocity
    (not zero once the leader moves) is fed forward row by row."""
    s = S.with_planner(PlannerKind.VIRTUAL_LEADER.value)
    brains = [AgentBrain(s, a) for a in (1, 2, 3)]
    for k in range(3):
        args: list[Args] = [(k, np.array([-100.0 + 20 * i, 10.0 * i]), SCAN if i == 1 else {}, [], [], 0.3 * i)
                            for i in range(3)]
        plans = [copy.deepcopy(b).plan(*a[:4], [], swarm(b), a[4], a[5]) for b, a in zip(brains, args, strict=True)]
        assert all(p.lead_vel is not None for p in plans)
        want = each_alone(brains, args)
        assert together(brains, args) == want


def test_a_plan_knowing_nothing_stacks_beside_one_that_knows_a_hull():
    brains = [AgentBrain(S, 1), AgentBrain(S, 2), AgentBrain(S, 4)]
    lone = Peer(9, 900.0, 900.0, 0.5)  # a lost robot far from everything: no group, no obstacle
    args: list[Args] = [(0, np.array([-500.0, 0.0]), {}, [], [], 0.0),  # knows nothing
                        (0, np.array([260.0, 0.0]), SCAN, [], [], 0.2),  # senses the diamond, 35 m from it
                        (0, np.array([-400.0, 10.0]), {}, [], [lone], 0.1)]  # nothing known, one lost robot far away
    want = each_alone(brains, args)
    assert together(brains, args) == want


def test_a_hull_is_never_skipped_when_the_agent_is_within_reach_of_its_farthest_vertex():
    """The plan skips hulls whose bounding circle (about the mean of the vertices) lies beyond repulsion reach. A
    lopsided hull: one vertex 10 m left of an arc of 17 (their mean lies right of the arc's centre): an agent
    1 cm within reach of that vertex, beyond it, gets the hull's distance in its table."""
    ang = np.radians(np.linspace(-80.0, 80.0, 17))
    hull = np.concatenate([[[-10.0, 0.0]], np.stack([np.cos(ang), np.sin(ang)], axis=1)])  # (about the origin)
    brain = AgentBrain(S, 1)
    brain.known.merge("lopsided", hull)
    brain.rev += 1  # (as a scan that found it would)
    assert brain.known.hulls["lopsided"].shape[0] == 18  # (every point a vertex)
    reach = float(brain.r[0]) + S.planner.d_max_m
    p = np.array([-10.0 - (reach - 0.01), 0.0])  # 1 cm within reach of the far vertex (a bound 4 cm short skips it)
    plan = brain.plan(0, p, {}, [], [], None, [])
    want = obstacle_view(p.reshape(1, 2), 1, 1, np.zeros(1, dtype=np.int64), np.arange(1),
                         Edges.of([brain.known.hulls["lopsided"]]))
    assert plan.ob.valid.tolist() == [[True]] and plan.ob.d.tolist() == want.d.tolist()
    assert abs(float(plan.ob.d[0, 0]) - (reach - 0.01)) < 1e-9
