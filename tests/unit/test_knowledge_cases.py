"""Obstacle knowledge (reconswarm/paper/knowledge.py), case by case: what the in-process engine reads from
`SwarmKnowledge` (`known`, `hulls`, `version`, `union_hull_before`) stays true to the bits after every kind
of step, the incremental `update` survives a restart by `add`/`share`, narrow fields and many agents, and
`KnownObstacles.merge_all` reports growth of any obstacle, not only of the last one it merges."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.geometry.plane import convex_hull
from reconswarm.paper import knowledge_bits
from reconswarm.paper.knowledge import KnownObstacles, SwarmKnowledge
from tests.unit.test_sensing_knowledge import FIELD, swarm_for

NO_LINKS = np.zeros((0, 2), dtype=np.int64)
NOTHING = np.zeros(0, dtype=np.int64)  # no agents, no samples


@pytest.fixture(autouse=True, scope="module", params=["dense", "sparse"])
def storage(request: pytest.FixtureRequest) -> Iterator[str]:
    """Every case runs over both storages of SwarmKnowledge (the size rule made to pick each)."""
    old = knowledge_bits.DENSE_MAX_BYTES
    knowledge_bits.DENSE_MAX_BYTES = 2**62 if request.param == "dense" else -1
    yield request.param
    knowledge_bits.DENSE_MAX_BYTES = old


def square_field(n_agents: int) -> SwarmKnowledge:
    """One obstacle of 8 contour samples (a square, corners and mid-sides): one byte of bits per agent."""
    pts = np.array([[0, 0], [1, 0], [2, 0], [2, 1], [2, 2], [1, 2], [0, 2], [0, 1]], dtype=np.float64)
    return SwarmKnowledge(pts, np.array([0]), np.array([8]), n_agents)


def reference(sk: SwarmKnowledge, bits: np.ndarray, l: int) -> list[np.ndarray | None]:
    """Each agent's hull of obstacle l from its bits alone (None: it knows nothing of l)."""
    out: list[np.ndarray | None] = []
    for i in range(bits.shape[0]):
        block = bits[i, sk.b0[l]:sk.b1[l]]
        flags = np.unpackbits(block)[: int(sk.count[l])].astype(bool)
        s0 = int(sk.start[l])
        pts = sk.samples[s0:s0 + int(sk.count[l])][flags]
        out.append(convex_hull(pts) if pts.shape[0] else None)
    return out


def test_merge_all_reports_growth_of_any_obstacle_not_only_the_last():
    k = KnownObstacles()
    s = FIELD.samples
    a, b = s[FIELD.start[1]:FIELD.start[1] + 6], s[FIELD.start[0]:FIELD.start[0] + 6]  # "a-tri" sorts first
    assert k.merge_all({"b-hex": a})
    # a-tri grows, b-hex (merged after it) does not: the set grew.
    assert k.merge_all({"a-tri": b, "b-hex": a[1:4]})
    assert not k.merge_all({"a-tri": b, "b-hex": a})


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 8), st.integers(2, 10), st.sampled_from(["update", "add+share"]))
def test_known_hulls_and_version_follow_the_bits_after_every_step(seed, n, ticks, path):
    """What the engine reads: `known` is `knows(l)` for every l, `hulls(rows, l)` is each agent's hull of
    its bits (a stale cached hull is never returned), and `version` moves whenever the bits did."""
    rng = np.random.default_rng(seed)
    sk = swarm_for(FIELD, n)
    rows = np.arange(n, dtype=np.int64)
    for _ in range(ticks):
        m = int(rng.integers(FIELD.n_obstacles))
        s0, sc = int(FIELD.start[m]), int(FIELD.count[m])
        agents = rng.integers(0, n, int(rng.integers(0, 5))).astype(np.int64)
        samples = (s0 + rng.integers(0, sc, agents.size)).astype(np.int64)
        links = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.3],
                         dtype=np.int64).reshape(-1, 2)
        before, v0 = sk.bits.copy(), sk.version
        if path == "update":
            sk.update(agents, samples, links)
        else:
            sk.add(agents, samples)
            sk.share(before, links)
        if not np.array_equal(before, sk.bits):
            assert sk.version > v0
        for l in range(FIELD.n_obstacles):
            assert np.array_equal(sk.known[:, l], sk.knows(l))
            assert np.array_equal(sk.knows_rows(l, rows[::-1]), sk.knows(l)[::-1])
            knowing = rows[sk.known[:, l]]
            want = [h for h in reference(sk, sk.bits, l) if h is not None]
            got = sk.hulls(knowing, l)
            assert len(got) == len(want) and all(np.array_equal(g, w) for g, w in zip(got, want, strict=True))


def test_version_only_grows():
    sk = swarm_for(FIELD, 2)
    seen = [sk.version]
    s0 = int(FIELD.start[0])
    sk.add(np.array([0]), np.array([s0]))
    seen.append(sk.version)
    sk.share(sk.bits.copy(), np.array([[0, 1]]))
    seen.append(sk.version)
    sk.add(np.array([1]), np.array([s0 + 1]))
    seen.append(sk.version)
    sk.update(np.array([0]), np.array([s0 + 2]), NO_LINKS)
    seen.append(sk.version)
    assert seen == sorted(seen) and len(set(seen)) == len(seen)


def test_update_after_add_still_shares_what_add_brought():
    """`add` restarts the incremental state: the next `update` over a link shares what was added."""
    sk = swarm_for(FIELD, 3)
    s0 = int(FIELD.start[2])
    sensed = np.arange(s0, s0 + 5, dtype=np.int64)
    sk.add(np.zeros(sensed.size, dtype=np.int64), sensed)
    sk.update(NOTHING, NOTHING, np.array([[0, 1]]))
    assert sk.knows(2).tolist() == [True, True, False]
    assert np.array_equal(sk.hull(1, 2), convex_hull(FIELD.samples[sensed]))
    # ... and again after `share`, over a link that existed at the update before.
    prev = sk.bits.copy()
    sk.share(prev, np.array([[1, 2]]))
    sk.update(NOTHING, NOTHING, np.array([[0, 1], [1, 2]]))
    assert sk.knows(2).tolist() == [True, True, True]


def test_a_field_of_one_byte_is_sensed_and_shared():
    for path in ("update", "add+share"):
        sk = square_field(2)
        assert sk.bits.shape == (2, 1)
        if path == "update":
            sk.update(np.array([0, 0, 0]), np.array([0, 2, 4]), NO_LINKS)
            sk.update(NOTHING, NOTHING, np.array([[0, 1]]))
        else:
            sk.add(np.array([0, 0, 0]), np.array([0, 2, 4]))
            sk.share(sk.bits.copy(), np.array([[0, 1]]))
        tri = convex_hull(sk.samples[[0, 2, 4]])
        assert np.array_equal(sk.hull(0, 0), tri), path
        assert np.array_equal(sk.hull(1, 0), tri), path


def test_links_of_many_agents_over_few_bytes_never_pass_for_one_another():
    """Five agents, one byte of bits each: the link 1-2 after the link 0-3 is a new link (a key of a link
    made from the byte count instead of the agent count would call them the same), so 1 learns 2's bits."""
    sk = square_field(5)
    sk.update(np.array([2, 0]), np.array([1, 5]), NO_LINKS)  # agent 2 senses sample 1, agent 0 sample 5
    sk.update(NOTHING, NOTHING, np.array([[0, 3]]))  # 3 learns 0's sample
    sk.update(NOTHING, NOTHING, np.array([[0, 3]]))  # the same link again: nothing changes
    sk.update(NOTHING, NOTHING, np.array([[1, 2]]))  # a new link: 1 learns all 2 knows
    assert sk.knows(0).tolist() == [True, True, True, True, False]
    assert np.array_equal(sk.hull(1, 0), sk.samples[[1]])
    assert np.array_equal(sk.hull(3, 0), sk.samples[[5]])


def test_hull_grows_from_an_earlier_hull_only_when_the_earlier_bits_are_included():
    sk = square_field(1)
    corners = np.array([0b10101000], dtype=np.uint8)  # samples 0, 2, 4: a triangle
    other = np.array([0b00000010], dtype=np.uint8)  # sample 6 only
    tri = sk.hull_of_bits(0, corners)
    assert np.array_equal(tri, convex_hull(sk.samples[[0, 2, 4]]))
    # An earlier (block, hull) that is not part of the block is not grown from: the hull is the block's.
    assert np.array_equal(sk.hull_of_bits(0, other, (corners, tri)), sk.samples[[6]])
    both = corners | other
    assert np.array_equal(sk.hull_of_bits(0, both, (corners, tri)), convex_hull(sk.samples[[0, 2, 4, 6]]))


def test_union_before_any_update_is_nothing():
    sk = swarm_for(FIELD, 3)
    assert all(sk.union_hull_before(l) is None for l in range(FIELD.n_obstacles))
    s0 = int(FIELD.start[1])
    sk.update(np.array([0, 1]), np.array([s0, s0 + 3]), NO_LINKS)
    assert sk.union_hull_before(1) is None  # the union before this update
    sk.update(NOTHING, NOTHING, NO_LINKS)
    union = sk.union_hull_before(1)
    assert union is not None and np.array_equal(union, convex_hull(FIELD.samples[[s0, s0 + 3]]))


def test_a_field_without_obstacles_knows_nothing_and_steps_fine():
    sk = SwarmKnowledge(np.zeros((0, 2)), NOTHING, NOTHING, 3)
    assert sk.bits.shape == (3, 0)
    sk.update(NOTHING, NOTHING, np.array([[0, 1]]))
    sk.add(NOTHING, NOTHING)
    sk.share(sk.bits.copy(), np.array([[0, 1], [1, 2]]))
    assert sk.bits.shape == (3, 0) and sk.known.shape == (3, 0)


def test_known_after_share_includes_what_was_shared():
    """`share` brings bits over links; `known` (what the engine reads to pick who knows an obstacle) says so."""
    sk = swarm_for(FIELD, 3)
    s0 = int(FIELD.start[0])
    sk.add(np.array([0]), np.array([s0]))
    sk.share(sk.bits.copy(), np.array([[0, 1]]))
    assert sk.known[:, 0].tolist() == [True, True, False]
    assert np.array_equal(sk.hulls(np.array([0, 1]), 0)[1], FIELD.samples[[s0]])


def test_memory_grows_with_what_agents_know_not_with_agents_times_samples():
    """A large swarm over a long contour holds no bit for agents that know nothing: building the tables and a
    tick where two agents learn an obstacle allocate far less than a bit per contour sample per agent."""
    import tracemalloc

    n = 200_000
    pts = np.stack([np.arange(40_000, dtype=np.float64), np.zeros(40_000)], axis=1)
    pts[::2, 1] = 1.0  # (a zigzag: the samples are not collinear)
    dense = n * 40_000 // 8  # 1 GB
    tracemalloc.start()
    try:
        sk = SwarmKnowledge(pts, np.array([0, 20_000]), np.array([20_000, 20_000]), n, dense=False)
        sk.update(np.array([5]), np.array([20_003]), NO_LINKS)
        sk.update(NOTHING, NOTHING, np.array([[5, 6]]))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert sk.known[:, 1].sum() == 2 and not sk.known[:, 0].any()
    assert np.array_equal(sk.hull(6, 1), pts[[20_003]])
    assert peak < dense / 20, peak
