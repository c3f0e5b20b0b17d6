"""The run record's `intrusions` table and the summary fields built from it."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np

from reconswarm.net.trust.admission import Intrusion, IntrusionKind
from reconswarm.net.trust.tally import IntrusionTally
from reconswarm.net.wire.keys import Keys
from reconswarm.record.store import RunRecord, RunWriter
from reconswarm.record.summary import summarize
from reconswarm.scenario.model import load
from tests.support import PAPER


def _record(db: Path) -> None:
    s = load(PAPER)
    n = len(s.agents)
    w = RunWriter(db, s, "lockstep")
    w.tick(0, 0.0, s.starts, s.headings, np.ones(n, bool), 1.0, 5.0, 5.0, 1)
    keys = Keys("paper-0a1b2c")
    world, agent3 = IntrusionTally(), IntrusionTally()
    for _ in range(5):
        world.add(Intrusion(IntrusionKind.IMPERSONATION, "zid-x", keys.host(2, "cmd"), "agent 2 speaks from zid-2"),
                  3.5)
    agent3.add(Intrusion(IntrusionKind.UNKNOWN_AGENT, "zid-x", keys.host_beacons((0, 0), 99), "agent 99"), 4.0)
    agent3.add(Intrusion(IntrusionKind.NOT_FROM_WORLD, "zid-y", keys.clock, "end"), 6.0)
    w.intrusions("simworld", world.as_rows())
    w.intrusions("agent-3", agent3.as_rows())
    world.add(Intrusion(IntrusionKind.IMPERSONATION, "zid-x", keys.host(2, "cmd"), "again"), 9.0)
    w.intrusions("simworld", world.as_rows())  # a later report replaces the earlier one
    w.close(finished="1")


def test_intrusions_in_the_record_and_the_summary(tmp_path: Path) -> None:
    db = tmp_path / "run.db"
    _record(db)
    rec = RunRecord(db)
    rows = rec.intrusions()
    s = summarize(rec)
    rec.close()
    assert [(r["process"], r["kind"], r["source"], r["count"], r["first_t"]) for r in rows] == [
        ("simworld", "impersonation", "zid-x", 6, 3.5), ("agent-3", "unknown_agent", "zid-x", 1, 4.0),
        ("agent-3", "not_from_world", "zid-y", 1, 6.0)]
    assert s["intrusions"] == 8
    assert s["intrusions_by_kind"] == {"impersonation": 6, "unknown_agent": 1, "not_from_world": 1}
    assert s["intrusion_sources"] == ["zid-x", "zid-y"]


def test_a_record_without_the_table_reads_as_no_intrusion(tmp_path: Path) -> None:
    db = tmp_path / "run.db"
    _record(db)
    with sqlite3.connect(db) as c:
        c.execute("DROP TABLE intrusions")
    rec = RunRecord(db)
    s = summarize(rec)
    rec.close()
    assert s["intrusions"] == 0 and s["intrusion_sources"] == []
