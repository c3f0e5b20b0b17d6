"""run.db's storage: the page size follows the swarm's size, and what is written reads back exactly."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest

from reconswarm.record.store import RunRecord, RunWriter
from reconswarm.scenario.generate import generate


@pytest.mark.parametrize("n", [10, 300])
def test_a_large_swarm_is_recorded_on_large_pages_and_reads_back(tmp_path: Path, n: int) -> None:
    """Above 128 agents run.db uses 64 KiB pages (one tick row in one page); either way the ticks read back
    exactly, and appending to an existing record keeps its page size."""
    s = generate(n, 0, 1)
    db = tmp_path / "run.db"
    w = RunWriter(db, s, "inprocess")
    rng = np.random.default_rng(n)
    rows = [(rng.normal(size=(n, 2)), rng.normal(size=n)) for _ in range(5)]
    for k, (p, th) in enumerate(rows):
        w.tick(k, k * 0.05, p, th, np.ones(n, dtype=bool), 1.0, 2.0, 3.0, 1)
    w.close(finished="1")
    RunWriter(db, s, "inprocess", append=True).close()
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA page_size").fetchone()[0] == (65536 if n > 128 else 4096)
    con.close()
    with RunRecord(db) as rec:
        t = rec.ticks()
    assert t.px.tobytes() == np.stack([p[:, 0] for p, _ in rows]).tobytes()
    assert t.py.tobytes() == np.stack([p[:, 1] for p, _ in rows]).tobytes()
    assert t.theta.tobytes() == np.stack([th for _, th in rows]).tobytes()
