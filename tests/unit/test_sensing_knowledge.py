"""Sensing (reconswarm/plant/sensing.py) and obstacle knowledge with its sharing rule
(reconswarm/paper/knowledge.py)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Point, Polygon

from reconswarm.geometry.plane import convex_hull, merge_hull
from reconswarm.paper import knowledge_bits
from reconswarm.paper.knowledge import KnownObstacles, SwarmKnowledge
from reconswarm.plant.sensing import ContourField
from reconswarm.scenario.model import (
    AgentSpec,
    ObstacleSpec,
    PlannerConfig,
    PlannerKind,
    Scenario,
    ScenarioMeta,
    WorldConfig,
)

SETTINGS = settings(max_examples=60, deadline=None)


@pytest.fixture(autouse=True, scope="module", params=["dense", "sparse"])
def storage(request: pytest.FixtureRequest) -> Iterator[str]:
    """Every case runs over both storages of SwarmKnowledge (the size rule made to pick each)."""
    old = knowledge_bits.DENSE_MAX_BYTES
    knowledge_bits.DENSE_MAX_BYTES = 2**62 if request.param == "dense" else -1
    yield request.param
    knowledge_bits.DENSE_MAX_BYTES = old


def polygon(centre: tuple[float, float], size: float, k: int, rot: float, aspect: float = 0.7) -> np.ndarray:
    ang = rot + np.arange(k) * 2 * math.pi / k
    x, y = size * np.cos(ang), aspect * size * np.sin(ang)
    return np.stack([centre[0] + x, centre[1] + y], axis=1)


def scenario_with(obstacles: dict[str, np.ndarray], starts: np.ndarray | None = None, rv: float = 40.0,
                  link: float = 40.0) -> Scenario:
    if starts is None:
        starts = np.array([[-1000.0, -1000.0]])
    agents = tuple(AgentSpec(id=i + 1, start_m=(float(x), float(y)), radius_m=1.0, offset_m=(30.0 * i, 0.0))
                   for i, (x, y) in enumerate(starts))
    obs = tuple(ObstacleSpec(id=k, vertices_m=tuple((float(x), float(y)) for x, y in v))
                for k, v in sorted(obstacles.items()))
    return Scenario(ScenarioMeta("t", 0, 10.0, 0.05),
                    PlannerConfig(PlannerKind.RECONFIGURABLE, 0.08, 80.0, -65.0, 2.0, 10.0, rv, link),
                    WorldConfig(), (2000.0, 0.0), agents, obs)


FIELD_OBSTACLES = {
    "b-hex": polygon((60.0, 30.0), 25.0, 6, 0.3),
    "a-tri": polygon((-20.0, -10.0), 18.0, 3, 1.1, 0.9),
    "c-quad": polygon((10.0, 90.0), 30.5, 4, 0.05, 0.5),
}


FIELD = ContourField.from_scenario(scenario_with(FIELD_OBSTACLES))


# ------------------------------------------------------------------------------------------ sensing


def test_contour_samples_spacing_vertices_and_layout():
    assert FIELD.ids == ("a-tri", "b-hex", "c-quad")  # sorted: the canonical obstacle order
    assert FIELD.count.sum() == FIELD.samples.shape[0]
    for m, oid in enumerate(FIELD.ids):
        block = FIELD.samples[FIELD.start[m]:FIELD.start[m] + FIELD.count[m]]
        assert np.all(FIELD.owner[FIELD.start[m]:FIELD.start[m] + FIELD.count[m]] == m)
        gaps = np.hypot(*(np.roll(block, -1, axis=0) - block).T)
        assert gaps.max() <= 1.0 + 1e-12  # <= 1 m apart along the closed contour
        poly = FIELD.polygons[m]
        for v in poly:  # every vertex is a sample
            assert np.any(np.all(block == v, axis=1))
        ext = Polygon(poly).exterior
        assert max(ext.distance(Point(*q)) for q in block) < 1e-9  # and every sample is on the contour
        perimeter = ext.length
        assert perimeter <= block.shape[0] <= perimeter + poly.shape[0]  # no more samples than needed
        np.testing.assert_array_equal(poly, np.array(FIELD_OBSTACLES[oid]))


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.integers(1, 30), st.floats(5.0, 60.0))
def test_scan_returns_exactly_the_samples_within_range(seed, n, rv):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-80, 140, (n, 2))
    want = {(i, s) for i in range(n) for s in range(FIELD.samples.shape[0])
            if math.sqrt((p[i, 0] - FIELD.samples[s, 0]) ** 2 + (p[i, 1] - FIELD.samples[s, 1]) ** 2) <= rv}
    variants = [FIELD.true_distances(p), FIELD.true_distances(p, exact_within_m=rv),
                FIELD.true_distances(p, rv, np.ones(n))]
    for true_d in variants:
        a, s = FIELD.scan(p, rv, true_d)
        got = list(zip(a.tolist(), s.tolist(), strict=True))
        assert got == sorted(want)  # exact set, sorted by agent then sample
        assert a.dtype == np.int64 and s.dtype == np.int64


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.floats(1.0, 50.0), st.sampled_from([12, 100]))
def test_true_distances_exact_near_and_a_lower_bound_far(seed, within, n):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-300, 400, (n, 2))  # n * M above 256: bounds far away; below: exact everywhere
    exact = FIELD.true_distances(p)
    for i in range(p.shape[0]):
        for m in range(FIELD.n_obstacles):
            shape = Polygon(FIELD.polygons[m])
            pt = Point(*p[i])
            want = -shape.exterior.distance(pt) if shape.contains(pt) else shape.distance(pt)
            assert exact[i, m] == pytest.approx(want, abs=1e-9)
    fast = FIELD.true_distances(p, exact_within_m=within)
    close = exact <= within
    # Exact wherever it matters; elsewhere above the threshold and never above the truth.
    if close.any():
        np.testing.assert_array_equal(fast, exact)
    else:
        assert np.all(fast > within) and np.all(fast <= exact + 1e-9)
    radii = np.asarray(rng.uniform(1.0, 5.0, p.shape[0]), dtype=np.float64)
    eng = FIELD.true_distances(p, within, radii)  # also exact for the smallest surface gap
    np.testing.assert_array_equal(eng[close], exact[close])
    assert np.all(eng[~close] > within) and np.all(eng <= exact + 1e-9)
    assert (eng - radii[:, None]).min() == (exact - radii[:, None]).min()


# ------------------------------------------------------------------------------------------ knowledge


def swarm_for(field: ContourField, n: int) -> SwarmKnowledge:
    return SwarmKnowledge(FIELD.samples, FIELD.start, FIELD.count, n)


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.integers(1, 6))
def test_known_obstacles_and_swarm_knowledge_give_identical_hulls(seed, chunks):
    """The same sensed samples, merged in chunks per obstacle (agent process) or as bits (engine)."""
    rng = np.random.default_rng(seed)
    n = 3
    sk = swarm_for(FIELD, n)
    known = [KnownObstacles() for _ in range(n)]
    for _ in range(chunks):
        for i in range(n):
            # A contiguous run of the contour (what a sensing disk sees), or a random scatter of samples.
            m = int(rng.integers(FIELD.n_obstacles))
            s0, sc = int(FIELD.start[m]), int(FIELD.count[m])
            if rng.random() < 0.5:
                first, length = int(rng.integers(sc)), int(rng.integers(1, sc + 1))
                idx = s0 + (first + np.arange(length)) % sc
            else:
                idx = s0 + rng.choice(sc, int(rng.integers(1, 8)), replace=False)
            sk.add(np.full(idx.size, i, dtype=np.int64), idx.astype(np.int64))
            known[i].merge(FIELD.ids[m], FIELD.samples[idx])
    for i in range(n):
        for m, oid in enumerate(FIELD.ids):
            if oid in known[i].hulls:
                assert sk.knows(m)[i]
                assert np.array_equal(sk.hull(i, m), known[i].hulls[oid])
            else:
                assert not sk.knows(m)[i]


def test_known_obstacles_merge_reports_growth():
    k = KnownObstacles()
    block = FIELD.samples[FIELD.start[1]:FIELD.start[1] + FIELD.count[1]]
    assert not k.merge("b-hex", np.zeros((0, 2)))
    assert k.merge("b-hex", block[:5])
    assert not k.merge("b-hex", block[1:4])  # already inside: no change
    assert k.merge("b-hex", block[::7])
    assert k.merge_all({"b-hex": block, "a-tri": FIELD.samples[:3]})
    np.testing.assert_array_equal(k.hulls["b-hex"], convex_hull(FIELD.polygons[1]))
    assert [oid for oid, _ in k.sorted_items()] == ["a-tri", "b-hex"]
    assert not k.merge_all({"b-hex": block})


def hop(k_sets: list[KnownObstacles], scans: dict[int, dict[str, np.ndarray]], links: list[tuple[int, int]]
        ) -> list[KnownObstacles]:
    """The sharing rule, per agent, from hulls: K_i(k) = hull(K_i(k-1) ∪ scan_i(k) ∪ K_j(k-1), j linked)."""
    prev = [dict(k.hulls) for k in k_sets]
    out = []
    for i, k in enumerate(k_sets):
        new = KnownObstacles(dict(k.hulls))
        new.merge_all(scans.get(i, {}))
        for a, b in links:
            if i in (a, b):
                new.merge_all(prev[b if i == a else a])
        out.append(new)
    return out


def test_sharing_has_one_tick_delay_per_hop():
    """Three agents in a line, A-B and B-C linked, A-C not: what A senses at tick k reaches B at k+1, C at k+2."""
    p = np.array([[0.0, 0.0], [35.0, 0.0], [70.0, 0.0]])
    links = [(i, j) for i in range(3) for j in range(i + 1, 3) if math.dist(p[i], p[j]) <= 40.0]
    assert links == [(0, 1), (1, 2)]
    pairs = np.array(links, dtype=np.int64)
    sk = swarm_for(FIELD, 3)
    per_agent = [KnownObstacles() for _ in range(3)]
    m = 1
    sensed = np.arange(FIELD.start[m], FIELD.start[m] + 9, dtype=np.int64)
    k_sense = 4
    history = []
    for k in range(8):
        scan_a = (np.zeros(sensed.size, np.int64), sensed) if k == k_sense else (np.zeros(0, np.int64),) * 2
        prev = sk.bits.copy()
        sk.add(*scan_a)
        sk.share(prev, pairs)
        per_agent = hop(per_agent, {0: {FIELD.ids[m]: FIELD.samples[sensed]}} if k == k_sense else {}, links)
        history.append(sk.knows(m).tolist())
        for i in range(3):
            assert (FIELD.ids[m] in per_agent[i].hulls) == bool(sk.knows(m)[i])
            if FIELD.ids[m] in per_agent[i].hulls:
                assert np.array_equal(per_agent[i].hulls[FIELD.ids[m]], sk.hull(i, m))
    assert history[k_sense - 1] == [False, False, False]
    assert history[k_sense] == [True, False, False]
    assert history[k_sense + 1] == [True, True, False]
    assert history[k_sense + 2] == [True, True, True]
    want = convex_hull(FIELD.samples[sensed])
    for i in range(3):
        assert np.array_equal(sk.hull(i, m), want)
    # Nobody else's knowledge leaks into an unlinked agent, and the union is what A sensed.
    np.testing.assert_array_equal(sk.union_hull(m, sk.bits), want)
    assert sk.union_hull(0, sk.bits) is None


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 7), st.integers(2, 12))
def test_random_ticks_swarm_bits_equal_per_agent_hulls(seed, n, ticks):
    """Random scans and links over several ticks: the bitset engine and the per-agent hull rule agree."""
    rng = np.random.default_rng(seed)
    sk = swarm_for(FIELD, n)
    per_agent = [KnownObstacles() for _ in range(n)]
    for _ in range(ticks):
        scans: dict[int, dict[str, np.ndarray]] = {}
        qa, qs = [], []
        for i in range(n):
            if rng.random() < 0.4:
                m = int(rng.integers(FIELD.n_obstacles))
                s0, sc = int(FIELD.start[m]), int(FIELD.count[m])
                idx = s0 + (int(rng.integers(sc)) + np.arange(int(rng.integers(1, 12)))) % sc
                scans[i] = {FIELD.ids[m]: FIELD.samples[idx]}
                qa.append(np.full(idx.size, i))
                qs.append(idx)
        links = [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.3]
        prev = sk.bits.copy()
        if qa:
            sk.add(np.concatenate(qa).astype(np.int64), np.concatenate(qs).astype(np.int64))
        sk.share(prev, np.array(links, dtype=np.int64).reshape(-1, 2))
        per_agent = hop(per_agent, scans, links)
        for i in range(n):
            for m, oid in enumerate(FIELD.ids):
                assert (oid in per_agent[i].hulls) == bool(sk.knows(m)[i])
                if oid in per_agent[i].hulls:
                    assert np.array_equal(per_agent[i].hulls[oid], sk.hull(i, m))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 9), st.integers(2, 15))
def test_incremental_update_equals_add_then_share(seed, n, ticks):
    rng = np.random.default_rng(seed)
    a = swarm_for(FIELD, n)
    b = swarm_for(FIELD, n)
    links = [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.4]
    for _ in range(ticks):
        m = int(rng.integers(FIELD.n_obstacles))
        s0, sc = int(FIELD.start[m]), int(FIELD.count[m])
        agents = rng.integers(0, n, int(rng.integers(0, 6))).astype(np.int64)
        samples = (s0 + rng.integers(0, sc, agents.size)).astype(np.int64)
        # Links persist, appear and vanish from tick to tick (the incremental path treats them differently).
        links = sorted({lk for lk in links if rng.random() < 0.8}
                       | {(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.15})
        pairs = np.array(links, dtype=np.int64).reshape(-1, 2)
        prev = a.bits.copy()
        a.add(agents, samples)
        a.share(prev, pairs)
        b.update(agents, samples, pairs)
        assert np.array_equal(a.bits, b.bits)
        for mm in range(FIELD.n_obstacles):
            ua, ub = a.union_hull(mm, prev), b.union_hull_before(mm)
            assert (ua is None and ub is None) or (ua is not None and ub is not None and np.array_equal(ua, ub))


def test_merge_hull_of_partial_views_matches_full_knowledge():
    """Two agents seeing different sides of one obstacle: their shared hull is the hull of both views."""
    m = 2
    s0, sc = int(FIELD.start[m]), int(FIELD.count[m])
    left = FIELD.samples[s0:s0 + sc // 3]
    right = FIELD.samples[s0 + sc // 2:s0 + sc // 2 + sc // 3]
    h = merge_hull(convex_hull(left), right)
    assert np.array_equal(h, convex_hull(np.concatenate([left, right])))
    sk = swarm_for(FIELD, 2)
    sk.add(np.zeros(sc // 3, np.int64), np.arange(s0, s0 + sc // 3, dtype=np.int64))
    sk.add(np.ones(sc // 3, np.int64), np.arange(s0 + sc // 2, s0 + sc // 2 + sc // 3, dtype=np.int64))
    prev = sk.bits.copy()
    sk.share(prev, np.array([[0, 1]], dtype=np.int64))
    assert np.array_equal(sk.hull(0, m), h) and np.array_equal(sk.hull(1, m), h)
    # The known hull lies within the true obstacle: distances to it are never below the true distance.
    assert Polygon(FIELD.polygons[m]).buffer(1e-9).contains(Polygon(h))
