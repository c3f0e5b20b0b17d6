"""navground's behaviours behind the planner seam: what the adapter hands a behaviour (neighbours heard, hull edges,
the slot as target) and the velocity it returns, on known geometry."""

from __future__ import annotations

import numpy as np
import pytest

from reconswarm.errors import BadInput
from reconswarm.paper.deadlock import StallState, generator
from reconswarm.paper.planner import Neighbours
from reconswarm.planners import navground_behaviors, registry
from reconswarm.planners.seam import Tick, cruise_speed_mps
from reconswarm.scenario.model import PLANNERS, load
from tests.support import PAPER

core = pytest.importorskip("navground.core")

NAVGROUND = ("orca", "hrvo", "hl", "social-force")
SQUARE = np.array([[20.0, -4.0], [28.0, -4.0], [28.0, 4.0], [20.0, 4.0]])  # a hull ahead of the head point


def one_row(s, p=(0.0, 0.0), goal=(100.0, 0.0), heard=(), hulls=()) -> Tick:
    """Tick 0 for the scenario's first agent: head point p, slot goal (centre goal, no offset), peers heard at the
    given (x, y, r), the given hulls."""
    nb = Neighbours.empty(1) if not heard else Neighbours(
        np.array([[[x, y] for x, y, _ in heard]]), np.array([[r for _, _, r in heard]]), np.ones((1, len(heard)), bool))
    return Tick(0, s.meta.dt_s, np.array([p], dtype=np.float64), np.zeros(1), np.array([s.agents[0].radius_m]),
                np.array([goal], dtype=np.float64), np.zeros((1, 2)), None, StallState.create(1, 1, [generator(0, 1)]),
                heard=nb, hulls=[list(hulls)])


def test_every_scenario_planner_has_a_registry_entry() -> None:
    assert set(registry.REGISTRY) == set(PLANNERS)


@pytest.mark.parametrize("kind", NAVGROUND)
def test_the_adapter_hands_the_behaviour_the_heard_peers_the_hull_edges_and_the_slot(kind: str) -> None:
    s = load(PAPER).with_planner(kind)
    pl = navground_behaviors.NavgroundPlanner(s, [s.agents[0].id], navground_behaviors.BEHAVIOURS[kind], kind)
    pl.command(one_row(s, p=(1.0, 2.0), goal=(100.0, 5.0), heard=[(9.0, 1.0, 3.0), (-6.0, 4.0, 2.5)], hulls=[SQUARE]))
    b = pl.behaviours[0]
    st = b.environment_state
    assert [(n.position.tolist(), n.radius, n.velocity.tolist()) for n in st.neighbors] == \
        [([9.0, 1.0], 3.0, [0.0, 0.0]), ([-6.0, 4.0], 2.5, [0.0, 0.0])]  # at rest: the wire carries no velocity
    edges = [(e.p1.tolist(), e.p2.tolist()) for e in st.line_obstacles]
    assert edges == [(SQUARE[j].tolist(), SQUARE[(j + 1) % 4].tolist()) for j in range(4)]  # closed polygon
    assert b.target.position.tolist() == [100.0, 5.0] and b.position.tolist() == [1.0, 2.0]
    assert b.radius == pytest.approx(s.agents[0].radius_m) and b.safety_margin == pytest.approx(s.planner.d_safe_m)
    assert b.optimal_speed == pytest.approx(cruise_speed_mps(s)) and b.kinematics.is_wheeled() is False


@pytest.mark.parametrize("kind", NAVGROUND)
def test_in_the_open_the_velocity_points_at_the_slot_within_the_speed_bound(kind: str) -> None:
    s = load(PAPER).with_planner(kind)
    pl = registry.make(s, [s.agents[0].id])
    goal = np.array([60.0, 80.0])  # direction (0.6, 0.8)
    for k in range(20):  # (behaviours that relax toward their desired velocity need a few ticks)
        t = one_row(s, goal=tuple(goal))
        t.k = k
        u = pl.command(t)[0]
    assert np.linalg.norm(u) > 0.1 and np.linalg.norm(u) <= cruise_speed_mps(s) * (1 + 1e-6)
    assert float(u @ goal) / (np.linalg.norm(u) * np.linalg.norm(goal)) > 0.999


@pytest.mark.parametrize("kind", ["orca", "hl"])
def test_a_hull_or_a_peer_in_the_way_turns_or_slows_the_velocity(kind: str) -> None:
    """Straight at the slot through a known hull (or a peer standing on the line): the behaviour does not keep
    heading straight at full speed. (HRVO and social force in navground 0.7 give line obstacles no weight at this
    range: docs/planners.md.)"""
    s = load(PAPER).with_planner(kind)
    speed = cruise_speed_mps(s)
    for what in ({"hulls": [SQUARE - [8.0, 0.0]]}, {"heard": [(14.0, 0.0, 4.0)]}):
        pl = navground_behaviors.NavgroundPlanner(s, [s.agents[0].id], navground_behaviors.BEHAVIOURS[kind], kind)
        pl.velocity[0] = [speed, 0.0]  # already cruising at the slot
        u = pl.command(one_row(s, **what))[0]
        assert np.linalg.norm(u) <= speed * (1 + 1e-6)
        assert u[0] < 0.95 * speed or abs(u[1]) > 0.1 * speed, (what, u)


def test_a_missing_navground_is_one_line_naming_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import builtins

    real = builtins.__import__

    def no_navground(name: str, *args, **kwargs):
        if name.startswith("navground"):
            raise ImportError(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_navground)
    with pytest.raises(BadInput) as got:
        registry.require(load(PAPER).with_planner("hl"))
    assert str(got.value) == "planner hl: navground is not installed (pip install 'reconswarm[navground]')"
    assert navground_behaviors.MISSING.count("\n") == 0
