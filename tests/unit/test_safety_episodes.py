"""The safety monitor (reconswarm/record/safety.py) against its definition, computed here by brute force over
every pair: the smallest surface gaps, and episodes (a maximal stretch of ticks with a pair below 0: a
collision; below d_safe: a safety violation) that start and end when they should; the same whether the
caller passes the candidate pairs and their distances (as the engine does) or not. And the thresholds
exactly: a gap of exactly 0 is not a collision, exactly d_safe is not a violation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reconswarm.geometry.pairs import pairs_and_distances
from reconswarm.record.safety import SafetyMonitor, nearest_gap

D_SAFE = 2.0
Key = tuple[str, str, str]


def brute(p: np.ndarray, r: np.ndarray, ids: np.ndarray, ob_d: np.ndarray, obs: tuple[str, ...]
          ) -> tuple[float, float, dict[Key, float]]:
    """(smallest agent gap, smallest obstacle gap, every (kind, a, b) below its threshold now -> its gap)."""
    below: dict[Key, float] = {}
    gap_a = math.inf
    for i in range(len(p)):
        for j in range(i + 1, len(p)):
            g = math.dist(p[i], p[j]) - r[i] - r[j]
            gap_a = min(gap_a, g)
            for kind, limit in (("safety", D_SAFE), ("collision", 0.0)):
                if g < limit:
                    below[(kind, f"agent:{ids[i]}", f"agent:{ids[j]}")] = g
    gap_o = math.inf
    for i in range(len(p)):
        for m, name in enumerate(obs):
            g = float(ob_d[i, m] - r[i])
            gap_o = min(gap_o, g)
            for kind, limit in (("safety", D_SAFE), ("collision", 0.0)):
                if g < limit:
                    below[(kind, f"agent:{ids[i]}", f"obstacle:{name}")] = g
    return gap_a, gap_o, below


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("with_candidates", ["none", "pairs", "pairs and distances"])
@pytest.mark.parametrize("r_max", [3.0, 8.0])  # radii up to 8 m: pairs in contact up to 18 m apart
def test_gaps_and_episodes_are_those_of_every_pair(seed: int, with_candidates: str, r_max: float) -> None:
    rng = np.random.default_rng(seed)
    n, m = 9, 2
    ids = np.arange(3, 3 + n, dtype=np.int64) * 2  # ids are not indices
    r = rng.uniform(0.5, r_max, n)
    obs = ("a", "b")
    mon = SafetyMonitor(ids, r, obs, D_SAFE)
    p = rng.uniform(-4 * r_max, 4 * r_max, (n, 2))
    ob_d = rng.uniform(0.0, 8.0, (n, m))
    open_now: dict[Key, float] = {}
    seen_kinds = set()
    for k in range(40):
        if k % 4:  # held still every fourth tick (the candidates are then the same as before)
            p = p + rng.normal(0.0, r_max / 2, (n, 2))
            ob_d = np.clip(ob_d + rng.normal(0.0, 1.0, (n, m)), -1.0, None)
        if with_candidates == "none":
            got = mon.step(k * 0.1, p, ob_d)
        else:
            cand, cand_d = pairs_and_distances(p, 2 * float(r.max()) + mon.reach_m)
            got = mon.step(k * 0.1, p, ob_d, cand, cand_d if with_candidates == "pairs and distances" else None)
        gap_a, gap_o, below = brute(p, r, ids, ob_d, obs)
        tick_a, tick_o, started, ended = got
        assert tick_a == pytest.approx(gap_a, abs=1e-12) and tick_o == pytest.approx(gap_o, abs=1e-12)
        want_started = {key: g for key, g in below.items() if key not in open_now}
        assert {(e.kind, e.a, e.b): (e.t_start, e.gap_m) for e in started} == {
            key: (k * 0.1, pytest.approx(g, abs=1e-12)) for key, g in want_started.items()}
        assert set(ended) == set(open_now) - set(below)
        open_now = {key: open_now.get(key, k * 0.1) for key in below}
        assert mon.open == open_now
        seen_kinds |= {key[0] + key[2].split(":")[0] for key in below}
    assert seen_kinds == {"safetyagent", "collisionagent", "safetyobstacle", "collisionobstacle"}


@pytest.mark.parametrize("with_candidates", [False, True])
def test_exactly_touching_is_a_violation_not_a_collision_and_exactly_d_safe_is_neither(with_candidates: bool) -> None:
    """Agents 1-2 at gap exactly 0 and agents 3-4 at gap exactly d_safe while 5-6 are at 0.5 (below d_safe);
    agent 7 exactly touching an obstacle, agent 8 exactly d_safe from it, agent 9 at 0.5 from it."""
    ids = np.arange(1, 10, dtype=np.int64)
    r = np.ones(9)
    x = [0.0, 2.0, 100.0, 100.0 + 2.0 + D_SAFE, 200.0, 202.5, 300.0, 400.0, 500.0]
    p = np.array([[xi, 0.0] for xi in x])
    ob_d = np.full((9, 1), 50.0)
    ob_d[6:, 0] = [1.0, 1.0 + D_SAFE, 1.5]  # centre to the obstacle; minus the radius 1: 0, d_safe, 0.5
    mon = SafetyMonitor(ids, r, ("box",), D_SAFE)
    if with_candidates:
        cand, cand_d = pairs_and_distances(p, 2.0 + mon.reach_m)
        tick_a, tick_o, started, _ = mon.step(0.0, p, ob_d, cand, cand_d)
    else:
        tick_a, tick_o, started, _ = mon.step(0.0, p, ob_d)
    assert (tick_a, tick_o) == (0.0, 0.0)
    assert sorted((e.kind, e.a, e.b, e.gap_m) for e in started) == [
        ("safety", "agent:1", "agent:2", 0.0),
        ("safety", "agent:5", "agent:6", 0.5),
        ("safety", "agent:7", "obstacle:box", 0.0),
        ("safety", "agent:9", "obstacle:box", 0.5),
    ]


def test_one_robot_has_no_pair_and_no_agent_gap() -> None:
    mon = SafetyMonitor(np.array([4]), np.array([1.0]), ("box",), D_SAFE)
    tick_a, tick_o, started, ended = mon.step(0.0, np.array([[0.0, 0.0]]), np.array([[5.0]]))
    assert (tick_a, tick_o, started, ended) == (math.inf, 4.0, [], [])


@pytest.mark.parametrize("seed", range(8))
def test_nearest_gap_leaves_out_points_not_finite_in_either_coordinate(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 60))
    p = rng.uniform(-10.0, 10.0, (n, 2)) * float(rng.choice([1.0, 30.0, 1000.0]))
    r = rng.uniform(0.1, 4.0, n)
    bad = rng.choice(n, 2, replace=False)
    p[bad[0], 0], p[bad[1], 1] = np.nan, np.inf  # one coordinate each
    keep = np.setdiff1d(np.arange(n), bad)
    want = min(math.dist(p[i], p[j]) - r[i] - r[j] for a, i in enumerate(keep) for j in keep[a + 1:])
    assert nearest_gap(p, r) == pytest.approx(want, abs=1e-9)
    assert nearest_gap(p[bad], r[bad]) == math.inf
    assert nearest_gap(p[keep[:2]], r[keep[:2]]) == pytest.approx(math.dist(p[keep[0]], p[keep[1]]) - r[keep[0]]
                                                                  - r[keep[1]], abs=1e-9)


def test_two_robots_in_contact_are_a_pair() -> None:
    mon = SafetyMonitor(np.array([1, 2]), np.array([1.0, 1.0]), (), D_SAFE)
    tick_a, _, started, _ = mon.step(0.0, np.array([[0.0, 0.0], [1.5, 0.0]]), np.zeros((2, 0)))
    assert tick_a == -0.5 and sorted(e.kind for e in started) == ["collision", "safety"]


def test_nearest_gap_finds_a_close_pair_of_large_robots_beyond_its_first_search_radius() -> None:
    """100 small robots (r 0.1) 10 m apart (gaps 9.8) and, to the side, two of r 20 whose centres are 45 m
    apart (gap 5): the nearest centres are not the nearest surfaces; the search must go on past the small
    pairs' radius until no pair beyond it can have a smaller gap (a pair beyond R has a gap above R - 2 r_max)."""
    grid = np.array([[10.0 * i, 10.0 * j] for i in range(10) for j in range(10)])
    p = np.vstack([grid, [[200.0, 0.0], [245.0, 0.0]]])
    r = np.concatenate([np.full(100, 0.1), [20.0, 20.0]])
    assert nearest_gap(p, r) == pytest.approx(5.0)
    assert nearest_gap(grid, r[:100]) == pytest.approx(9.8)
