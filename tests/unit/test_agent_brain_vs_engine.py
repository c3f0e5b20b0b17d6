"""The real AgentBrain.tick, fed what an agent process receives, equals the in-process engine's row bit for bit.

The engine runs the paper mission; beside it every agent has its own AgentBrain, given at tick k exactly
what the lockstep protocol hands an agent: its head point at k, the contour points the world's sensing
gives it at k, every peer's beacon at k (head point, radius), and the obstacle sets at k-1 of the peers
within link range, each revision merged once (the sets are the engine's own knowledge of those peers at
k-1, announced with a revision that grows whenever that knowledge grew). Its command is compared with
the engine's u row with `==`.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.brain import AgentBrain, Peer
from reconswarm.geometry.plane import norm2
from reconswarm.paper.link import linked
from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import PlannerKind, Scenario, load
from reconswarm_bringup.engine import Engine
from tests.support import PAPER

TICKS = 1000  # until the swarm is well into the diamond (knowledge sensed, shared and repelling)
STALL_TICKS = 700  # generate(16, 4, 3): its first stall perturbation at tick 518, then more
LEADER_TICKS = 600


def side_by_side(s: Scenario, ticks: int) -> tuple[Engine, int, int]:
    """The engine and one AgentBrain per agent over `ticks` ticks, every command compared with `==`. Returns the
    engine, how many agent-ticks grew knowledge from peers' sets alone, and how many planned with known hulls."""
    eng = Engine(s)
    c, f, n = s.planner, eng.field, eng.n
    ids = [int(a) for a in s.ids]
    brains = [AgentBrain(s, a) for a in ids]
    leader = s.planner.kind == PlannerKind.VIRTUAL_LEADER
    rev = [0] * n  # revision of each agent's set, as its beacon would announce it
    sets: list[dict[str, np.ndarray]] = [{} for _ in range(n)]  # each agent's set at k-1
    merged = [[0] * n for _ in range(n)]  # merged[i][j]: j's revision that agent i merged last
    bits = eng.know.bits.copy()
    shared_grew = obstacle_rows = 0
    for k in range(ticks):
        p = eng.p.copy()
        for j in range(n):  # the sets at k-1 (the engine's knowledge before it plans tick k)
            if not np.array_equal(eng.know.bits[j], bits[j]):
                rev[j] += 1
                sets[j] = {f.ids[m]: eng.know.hull(j, m) for m in range(f.n_obstacles) if eng.know.knows(m)[j]}
        bits = eng.know.bits.copy()
        u = eng.plan(k)
        qa, qs = f.scan(p, c.sensing_range_m, eng.true_d)  # what the world senses for each agent at k
        for i in range(n):
            pts: dict[str, list[tuple[float, float]]] = {}
            for q in qs[qa == i].tolist():
                pts.setdefault(f.ids[int(f.owner[q])], []).append((float(f.samples[q, 0]), float(f.samples[q, 1])))
            # As arrays, or as the wire's (x, y) pairs (what an agent node hands its brain): both forms, alternately.
            scan = {oid: np.array(v, dtype=np.float64) for oid, v in pts.items()} if i % 2 else pts
            peers = [Peer(ids[j], float(p[j, 0]), float(p[j, 1]), float(eng.r[j])) for j in range(n) if j != i]
            shared = []
            for a in sorted(brains[i].linked(p[i], peers)):
                j = ids.index(a)
                if rev[j] > merged[i][j]:
                    shared.append(sets[j])
                    merged[i][j] = rev[j]
            swarm = [sets[j] for j in range(n) if j != i] if leader else None  # the leader's union: everyone's
            before = brains[i].rev
            ui, _grew = brains[i].tick(k, p[i].copy(), scan, peers, shared, swarm)
            assert ui.tolist() == u[i].tolist(), (k, ids[i], ui, u[i])  # `==` on floats: bit for bit
            shared_grew += bool(shared) and brains[i].rev > before and not scan
            obstacle_rows += brains[i].rev > 0
        eng.advance(u)
    return eng, shared_grew, obstacle_rows


def test_agent_brain_tick_equals_the_engine_row_bit_for_bit() -> None:
    s = load(PAPER)
    eng, shared_grew, obstacle_rows = side_by_side(s, TICKS)
    # The check covered knowledge received only from peers and commands with known obstacles around.
    assert shared_grew > 0 and obstacle_rows > 1000
    assert np.min(eng.field.true_distances(eng.p)[:, 0] - eng.r) < s.planner.d_max_m


def test_agent_brain_equals_the_engine_through_stall_perturbations() -> None:
    """Remark 1's escape (each agent's own stall window, the push along its current repulsion): a scenario that
    stalls against its obstacles, until a perturbation has acted for a while."""
    s = generate(16, 4, 3)
    eng, _, obstacle_rows = side_by_side(s, STALL_TICKS)
    assert int(eng.stall.stalls.sum()) >= 1 and obstacle_rows > 0


def test_agent_brain_equals_the_engine_under_the_virtual_leader() -> None:
    """The benchmark: each agent's copy of the leader from the union of everyone's sets, its velocity fed forward,
    the containment wall."""
    s = load(PAPER).with_planner(PlannerKind.VIRTUAL_LEADER.value)
    _, _, obstacle_rows = side_by_side(s, LEADER_TICKS)
    assert obstacle_rows > 100


_coord = st.floats(-50.0, 50.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(p=st.tuples(_coord, _coord), peers=st.lists(st.tuples(_coord, _coord), max_size=12),
       on_edge=st.lists(st.floats(0.0, 6.283), max_size=4))
def test_linked_at_is_the_link_rule_of_the_engine(p: tuple[float, float], peers: list[tuple[float, float]],
                                                  on_edge: list[float]) -> None:
    """AgentBrain.linked_at (one peer at a time) picks exactly the peers that reconswarm.paper.link.linked picks
    from norm2 distances (the engine's rule), peers at the link range's edge included."""
    s = load(PAPER)
    brain, link_m = AgentBrain(s, int(s.ids[0])), s.planner.link_range_m
    at_edge = [(p[0] + link_m * float(np.cos(a)), p[1] + link_m * float(np.sin(a))) for a in on_edge]
    at = {j: Peer(j, x, y, 0.5) for j, (x, y) in enumerate([*peers, *at_edge])}
    q = np.array([(b.px, b.py) for b in at.values()]).reshape(-1, 2)
    want = [j for j, ok in zip(at, linked(norm2(np.array(p)[None, :] - q), link_m), strict=True) if ok]
    assert brain.linked_at(np.array(p), at) == want


@settings(max_examples=200, deadline=None)
@given(p=st.tuples(_coord, _coord), peers=st.lists(st.tuples(_coord, _coord, st.floats(0.1, 2.0)), max_size=12),
       on_edge=st.lists(st.floats(0.0, 6.283), max_size=4))
def test_neighbours_are_the_planners_reach(p: tuple[float, float], peers: list[tuple[float, float, float]],
                                           on_edge: list[float]) -> None:
    """AgentBrain._neighbours (one peer at a time) keeps exactly the peers within r_i + r_j + d_max by norm2 over
    arrays, in increasing id, peers at the reach's edge included."""
    s = load(PAPER)
    brain = AgentBrain(s, int(s.ids[0]))
    r, d_max = float(brain.r[0]), s.planner.d_max_m
    at_edge = [(p[0] + (2 * r + d_max) * float(np.cos(a)), p[1] + (2 * r + d_max) * float(np.sin(a)), r)
               for a in on_edge]
    everyone = [Peer(j, x, y, rad) for j, (x, y, rad) in reversed(list(enumerate([*peers, *at_edge])))]
    pos = np.array([p])
    q = np.array([(b.px, b.py) for b in everyone]).reshape(-1, 2)
    rr = np.array([b.radius for b in everyone])
    keep = norm2(pos - q) <= brain.r[0] + rr + d_max
    want = sorted((b for b, k in zip(everyone, keep, strict=True) if k), key=lambda b: b.id)
    got = brain._neighbours(pos, everyone)
    assert got.p.reshape(-1, 2).tolist() == [[b.px, b.py] for b in want]
    assert got.r.reshape(-1).tolist() == [b.radius for b in want]


NAVGROUND_TICKS = 1100  # the swarm meets the diamond: hulls sensed, shared and given to the behaviours


@pytest.mark.parametrize("kind", ["orca", "hrvo", "hl", "social-force"])
def test_agent_brain_equals_the_engine_under_navground_planners(kind: str) -> None:
    """navground's behaviours, one per agent: the brain gives its behaviour the peers heard within link range and
    its known hulls in the engine's order, and the behaviour's state (its last command) evolves the same way."""
    pytest.importorskip("navground.core")
    s = load(PAPER).with_planner(kind)
    _, _, obstacle_rows = side_by_side(s, NAVGROUND_TICKS)
    assert obstacle_rows > 100
