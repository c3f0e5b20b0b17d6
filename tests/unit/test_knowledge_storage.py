"""SwarmKnowledge's two storages (reconswarm/paper/swarm_knowledge.py): which one the size rule picks, and
that the engine runs the same mission over either, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from reconswarm.paper import knowledge_bits
from reconswarm.paper.dense_knowledge import DenseKnowledge
from reconswarm.paper.knowledge import SwarmKnowledge
from reconswarm.paper.sparse_knowledge import SparseKnowledge
from reconswarm.scenario.generate import generate
from reconswarm_bringup.engine import Engine

TICKS = 700


def zigzag(samples: int) -> np.ndarray:
    pts = np.stack([np.arange(samples, dtype=np.float64), np.zeros(samples)], axis=1)
    pts[::2, 1] = 1.0
    return pts


def test_a_small_table_is_dense_a_large_one_sparse_and_either_can_be_asked_for():
    pts, start, count = zigzag(800), np.array([0, 400]), np.array([400, 400])  # 100 bytes an agent
    assert type(SwarmKnowledge(pts, start, count, 300)) is DenseKnowledge
    assert type(SwarmKnowledge(pts, start, count, 300, dense=False)) is SparseKnowledge
    at_limit = knowledge_bits.DENSE_MAX_BYTES // 100
    assert type(SwarmKnowledge(pts, start, count, at_limit)) is DenseKnowledge
    assert type(SwarmKnowledge(pts, start, count, at_limit + 1)) is SparseKnowledge  # (N x B over 64 MiB)
    assert type(SwarmKnowledge(pts, start, count, 2, dense=True)) is DenseKnowledge


@pytest.fixture
def storages(monkeypatch: pytest.MonkeyPatch) -> tuple[Engine, Engine]:
    """Engines over generate(16, 4, 3) (agents meet several obstacles, links come and go), dense then sparse."""
    s = generate(16, 4, 3)
    monkeypatch.setattr(knowledge_bits, "DENSE_MAX_BYTES", 2**62)
    dense = Engine(s)
    monkeypatch.setattr(knowledge_bits, "DENSE_MAX_BYTES", -1)
    sparse = Engine(s)
    assert type(dense.know) is DenseKnowledge and type(sparse.know) is SparseKnowledge
    return dense, sparse


def test_the_engine_runs_the_same_mission_over_either_storage(storages: tuple[Engine, Engine]):
    dense, sparse = storages
    for k in range(TICKS):
        u, v = dense.plan(k), sparse.plan(k)
        assert np.array_equal(u, v), k
        dense.advance(u)
        sparse.advance(v)
        assert np.array_equal(dense.p, sparse.p) and np.array_equal(dense.theta, sparse.theta), k
        assert np.array_equal(dense.know.known, sparse.know.known), k
        if k % 50 == 0 or k == TICKS - 1:
            assert np.array_equal(dense.know.bits, sparse.know.bits), k
    shared = (dense.know.known.sum(axis=0) > 1).sum()
    assert shared >= 2, "the case must share knowledge of several obstacles"
