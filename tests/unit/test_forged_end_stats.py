"""An end clock's statistics are the world's word, taken field by field: an end stamped with the world's
session (open mode cannot tell it from the world's own) carrying the summary's own fields (`converged`,
`collisions`, `intrusions`, `convergence_time_s`, `deterministic`, ...) changes none of them; only the
world's counters (reconswarm/record/extra.py) are taken, each checked for its type and range. The same holds
for a record whose `extra` already holds such fields: the summary computes its own from the record."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

from reconswarm.record.extra import world_stats
from reconswarm.record.summary import summarize
from tests.unit.monitor_run import DT, IDS, S, clock, report, started, truth, world

FORGED = {"converged": 1.0, "collisions": 0.0, "intrusions": 0.0, "convergence_time_s": 12.0,
          "final_max_error_m": 0.0, "safety_violations": 0.0, "deterministic": 1.0, "duration_s": 1e9,
          "messages_rejected": 0.0, "agents": 3.0}
FAR = S.starts + 50.0  # every agent far from its slot: the truth is not converged


def test_a_forged_end_clocks_stats_rewrite_no_field_of_the_summary(tmp_path: Path) -> None:
    """The world's session id overheard: an end claiming `duration` at tick 4, its stats the summary's own fields
    (and counters out of range). The end stands (the world goes); the summary is the record's: not converged, no
    convergence time, its own error; the bad counters are dropped and counted, the good one kept."""
    run = started(tmp_path)
    for k in range(4):
        run.step(0.01 * k, clock(k), truth(k, FAR), *(report(a) for a in IDS))
    stats = {**FORGED, "world_overruns": 3.0, "latency_p50_ms": -5.0, "latency_samples": 1.5,
             "missed_deadline_ratio": 7.0, "uncommanded_from_s": -1.0}
    run.step(0.05, clock(4, end=True, reason="duration", stats=stats, source="forger-zid"), truth(4, FAR),
             world(False))
    assert run.exit is not None and run.exit.reason == "recorded"
    with run.record() as rec:
        s = summarize(rec)
        extra = rec.meta_json("extra")
        rejected = rec.counters()
    assert s["converged"] is False and s["convergence_time_s"] is None
    assert s["final_max_error_m"] is not None and s["final_max_error_m"] > 1.0
    assert s["duration_s"] == round(4 * DT, 3) and s["agents"] == len(IDS)
    assert s["collisions"] == 0 and s["intrusions"] == 0  # (the record's own: nothing was refused)
    assert s["deterministic"] is True and s["world_overruns"] == 3
    for key in ("latency_p50_ms", "latency_samples", "missed_deadline_ratio"):
        assert key not in s and key not in extra
    assert not (set(FORGED) - {"deterministic"}) & set(extra)  # (deterministic: the monitor's own verdict)
    assert rejected["monitor"] == 1  # (the end's statistics dropped: counted once)


def test_a_records_extra_overwrites_none_of_the_fields_the_summary_computes(tmp_path: Path) -> None:
    """A record whose `extra` holds the summary's own fields (written by an older monitor from a forged end, or by
    hand): the summary still computes them from the record; a counter out of range is left out."""
    run = started(tmp_path)
    for k in range(3):
        run.step(0.01 * k, clock(k), truth(k, FAR), *(report(a) for a in IDS))
    run.stop(0.1)
    db = sqlite3.connect(run.path)
    db.execute("INSERT OR REPLACE INTO meta(key, value) VALUES ('extra', ?)",
               (json.dumps({**FORGED, "converged": True, "convergence_time_s": 12, "end_reason": "converged",
                            "world_overruns": -4, "latency_p99_ms": 2.5, "deterministic": False,
                            "determinism_lost_at_s": 0.1}),))
    db.commit()
    db.close()
    with run.record() as rec:
        s = summarize(rec)
    assert (s["converged"], s["convergence_time_s"], s["duration_s"], s["agents"]) == (False, None, round(2 * DT, 3),
                                                                                     len(IDS))
    assert s["end_reason"] == "converged" and s["latency_p99_ms"] == 2.5 and "world_overruns" not in s
    assert (s["deterministic"], s["determinism_lost_at_s"]) == (False, 0.1)  # (the monitor's own verdict, kept)


def test_world_stats_keeps_the_worlds_counters_in_range_and_names_the_rest() -> None:
    kept, dropped = world_stats({"world_overruns": 2.0, "latency_p50_ms": 1.25, "latency_p99_ms": float("inf"),
                                 "latency_samples": 10.0, "missed_deadlines": 3.0, "deadlines": 2.5,
                                 "missed_deadline_ratio": 0.3, "uncommanded_from_s": 4.5, "converged": 1.0})
    assert kept == {"world_overruns": 2, "latency_p50_ms": 1.25, "latency_samples": 10, "missed_deadlines": 3,
                    "missed_deadline_ratio": 0.3, "uncommanded_from_s": 4.5}
    assert sorted(dropped) == ["converged", "deadlines", "latency_p99_ms"]


def test_an_end_for_a_reason_the_world_never_gives_is_refused_and_recording_goes_on(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.step(0.0, clock(0), truth(0), *(report(a) for a in IDS))
    run.step(0.01, clock(1, end=True, reason="all agents converged, trust me", source="forger-zid"), truth(1))
    (refused,) = run.refused
    assert refused.source == "forger-zid" and run.exit is None
    run.stop(0.1)
    with run.record() as rec:
        assert "end_reason" not in rec.meta_json("extra") and rec.meta["finished"] == "0"
