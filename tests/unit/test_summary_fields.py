"""The run summary's fields (reconswarm/record/summary.py, their meaning: docs/wire.md) from small hand-made
records with known answers: convergence time (the start of the final stretch within tolerance), the agents
lost (last membership event), intrusions counted once per message (per kind and source, the most any one
process refused), path lengths (unknown positions skipped), rounding, the world's counts as whole numbers,
and how the table reads."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rich.console import Console

from reconswarm.paper.events import Event, EventKind
from reconswarm.record.store import RunRecord, RunWriter
from reconswarm.record.summary import (
    convergence_time,
    distinct_intrusions,
    lost_agents,
    render,
    summarize,
)
from reconswarm.scenario.generate import generate

# ------------------------------------------------------------------------------------------ helpers


def test_convergence_time_is_the_start_of_the_final_stretch_within_tolerance() -> None:
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    assert convergence_time(t, np.array([5.0, 0.4, 0.6, 0.5, 0.2, 0.1]), 0.5) == pytest.approx(0.3)  # 0.5: within
    assert convergence_time(t, np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.5]), 0.5) == pytest.approx(0.0)  # always
    assert convergence_time(t, np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.51]), 0.5) is None  # left at the end
    assert convergence_time(t, np.array([0.1, 0.1, np.nan, 0.1, 0.1, 0.1]), 0.5) == pytest.approx(0.3)  # unknown
    assert convergence_time(t, np.array([0.1, 0.1, 0.1, 0.1, 0.1, np.nan]), 0.5) is None
    assert convergence_time(np.zeros(0), np.zeros(0), 0.5) is None


def test_lost_agents_are_those_whose_last_membership_event_is_a_loss() -> None:
    events: list[dict[str, Any]] = [
        {"kind": "agent_lost", "agent": 4}, {"kind": "agent_lost", "agent": 2},
        {"kind": "split", "before": [[1, 2]], "after": [[1], [2]]},
        {"kind": "agent_joined", "agent": 4},  # back
        {"kind": "agent_lost", "agent": 7}, {"kind": "agent_joined", "agent": 9},
        {"kind": "world_stalled", "agent": 3},  # not a membership event
        {"kind": "agent_lost"},  # no agent named
    ]
    assert lost_agents(events) == [2, 7]


def test_intrusions_count_each_message_once_and_each_process_its_own() -> None:
    rows = [  # a forged clock heard by the monitor and two agents (one came late), and two sources of commands
        {"process": "monitor", "kind": "not_from_world", "source": "x", "count": 7},
        {"process": "agent-1", "kind": "not_from_world", "source": "x", "count": 7},
        {"process": "agent-2", "kind": "not_from_world", "source": "x", "count": 3},
        {"process": "simworld", "kind": "impersonation", "source": "x", "count": 4},
        {"process": "simworld", "kind": "impersonation", "source": "y", "count": 5},
        {"process": "simworld", "kind": "command", "source": "y", "count": 1},
    ]
    by_kind, by_process = distinct_intrusions(rows)
    assert by_kind == {"not_from_world": 7, "impersonation": 9, "command": 1}
    assert by_process == {"monitor": 7, "agent-1": 7, "agent-2": 3, "simworld": 10}


# ------------------------------------------------------------------------------------------ a record


S = generate(3, 1, 1)


def write(tmp_path: Path, mode: str = "inprocess", **meta: object) -> Path:
    """Agent 0 walks 3-4-5 steps along (0.6, 0.8) (5 m each), agent 1 is unknown (NaN) at tick 2, agent 2
    stands; the largest error goes 9 -> 0.3 -> 0.2; agent 3 (id) lost, another lost and back."""
    db = tmp_path / "run.db"
    w = RunWriter(db, S, mode)
    n = len(S.agents)
    base = S.starts.copy()
    for k in range(4):
        p = base.copy()
        p[0] += k * np.array([3.0, 4.0])
        p[1, 0] += 1.2367 * k
        if k == 2:
            p[1] = np.nan
        err = [9.0, 9.0, 0.3, 0.2][k]
        w.tick(k, 0.05 * k, p, S.headings.copy(), np.ones(n, dtype=bool), err, [4.0, 1.23456, 2.0, 3.0][k],
               math.inf, 1)
    ids = [a.id for a in S.agents]
    w.event(Event(0.05, EventKind.AGENT_LOST, agent=ids[0]))
    w.event(Event(0.07, EventKind.AGENT_LOST, agent=ids[1]))
    w.event(Event(0.1, EventKind.AGENT_JOINED, agent=ids[1]))
    g = (tuple(ids),)
    w.event(Event(0.02, EventKind.SPLIT, before=g, after=((ids[0],), tuple(ids[1:]))))
    w.event(Event(0.03, EventKind.SPLIT, before=g, after=((ids[0], ids[1]), (ids[2],))))
    w.event(Event(0.04, EventKind.MERGE, before=((ids[0],), tuple(ids[1:])), after=g))
    w.counters({"simworld": 2, "agent-1": 0, "monitor": 3})
    w.intrusions("monitor", [("not_from_world", "x", 7, 0.1)])
    w.intrusions("agent-1", [("not_from_world", "x", 5, 0.2), ("impersonation", "y", 2, 0.3)])
    w.note_gap(0.05, 0.1, "a stall")
    w.close(**meta)
    return db


def test_summary_fields_of_a_hand_made_record(tmp_path: Path) -> None:
    db = write(tmp_path, wall_time_s="12.34567", finished="1",
               extra={"world_overruns": 3.0, "latency_samples": 2.5, "stalls": 0.0, "note": 1.0})
    with RunRecord(db) as rec:
        s = summarize(rec)
    ids = [a.id for a in S.agents]
    assert s["duration_s"] == pytest.approx(0.15) and s["ticks"] == 4 and s["finished"] is True
    assert S.planner.converge_tol_m == 0.5  # within it from tick 2 (0.3 m) to the end
    assert s["converged"] is True and s["convergence_time_s"] == pytest.approx(0.1)
    assert s["final_max_error_m"] == pytest.approx(0.2)
    assert s["min_agent_gap_m"] == 1.235 and s["min_obstacle_gap_m"] is None  # rounded to mm; none recorded
    assert s["agents_lost"] == [ids[0]]
    assert s["messages_rejected"] == 5 and s["messages_rejected_by_process"] == {"simworld": 2, "agent-1": 0,
                                                                              "monitor": 3}
    # agent 0: three 5 m steps; agent 1: 1.2367 m, then unknown (two steps skipped); agent 2: still.
    assert s["path_length_m"] == {str(ids[0]): 15.0, str(ids[1]): 1.24, str(ids[2]): 0.0}
    assert (s["splits"], s["merges"]) == (2, 1)
    assert (s["intrusions"], s["intrusions_by_kind"]) == (9, {"not_from_world": 7, "impersonation": 2})
    assert s["intrusions_by_process"] == {"monitor": 7, "agent-1": 7} and s["intrusion_sources"] == ["x", "y"]
    assert s["record_gaps"] == [{"t_from": 0.05, "t_to": 0.1, "note": "a stall"}]
    assert (s["scenario"], s["planner"], s["agents"], s["seed"]) == (S.meta.name, "reconfigurable", 3, S.meta.seed)
    assert s["determinism_lost_at_s"] is None
    assert s["wall_time_s"] == 12.346
    assert s["deterministic"] is True and s["mode"] == "inprocess"
    assert s["world_overruns"] == 3 and isinstance(s["world_overruns"], int)  # a count is whole
    assert s["stalls"] == 0 and isinstance(s["stalls"], int)
    assert "latency_samples" not in s and "note" not in s  # a count that is not whole, a field nobody writes


def test_a_record_of_no_tick_and_one_of_two_ticks(tmp_path: Path) -> None:
    db = tmp_path / "none.db"
    RunWriter(db, S, "lockstep").close()
    with RunRecord(db) as rec:
        s = summarize(rec)
    assert (s["duration_s"], s["final_max_error_m"], s["converged"], s["ticks"]) == (0.0, None, False, 0)
    assert set(s["path_length_m"].values()) == {0.0}
    db = tmp_path / "two.db"
    w = RunWriter(db, S, "lockstep")
    n = len(S.agents)
    for k in range(2):
        p = S.starts + np.array([3.0, 4.0]) * k
        w.tick(k, 0.05 * k, p, S.headings.copy(), np.ones(n, dtype=bool), 1.0, 2.0, 3.0, 1)
    w.close()
    with RunRecord(db) as rec:
        s = summarize(rec)
    assert set(s["path_length_m"].values()) == {5.0}


def test_the_records_own_names_come_before_the_scenarios(tmp_path: Path) -> None:
    """run.db's meta names the scenario and planner as launched (a sweep's file, a --planner override)."""
    db = tmp_path / "run.db"
    w = RunWriter(db, S, "lockstep")
    w.set_meta(scenario="sweep/g-3.toml", planner="virtual-leader")
    w.close()
    with RunRecord(db) as rec:
        s = summarize(rec)
    assert (s["scenario"], s["planner"]) == ("sweep/g-3.toml", "virtual-leader")


def test_a_record_of_one_tick_has_zero_paths_and_no_wall_time(tmp_path: Path) -> None:
    db = tmp_path / "run.db"
    w = RunWriter(db, S, "lockstep")
    n = len(S.agents)
    w.tick(0, 0.0, S.starts.copy(), S.headings.copy(), np.ones(n, dtype=bool), 1.0, 2.0, 3.0, 1)
    w.close()
    with RunRecord(db) as rec:
        s = summarize(rec)
    assert set(s["path_length_m"].values()) == {0.0} and len(s["path_length_m"]) == n
    assert s["wall_time_s"] is None and s["finished"] is False and s["deterministic"] is False


# ------------------------------------------------------------------------------------------ the table


def table_text(summary: dict) -> str:
    con = Console(width=200, record=True, color_system=None)
    con.print(render(summary))
    return con.export_text()


def test_the_table_condenses_paths_drops_empty_rows_and_says_yes_or_no(tmp_path: Path) -> None:
    with RunRecord(write(tmp_path, wall_time_s="3.0", finished="1")) as rec:
        s = summarize(rec)
    s["intrusions_by_kind"], s["record_gaps"] = {}, []  # (as in a run without any)
    text = table_text(s)
    lines = {ln.split("│")[1].strip(): ln.split("│")[2].strip() for ln in text.splitlines() if ln.count("│") >= 3}
    assert lines["path_length_m"] == "min 0.0, mean 5.4, max 15.0 m"
    assert lines["messages_rejected_by_process"] == "{'simworld': 2, 'monitor': 3}"  # zero counts left out
    assert lines["finished"] == "yes" and lines["converged"] == "yes" and lines["convergence_time_s"] == "0.1"
    assert "intrusions_by_kind" not in lines and "record_gaps" not in lines  # empty: no row
    assert lines["intrusion_sources"] == "['x', 'y']"
    assert "determinism_lost_at_s" not in lines  # nothing lost
    assert lines["min_obstacle_gap_m"] == "-"
    assert f"reconswarm run: {s['scenario']} (reconfigurable, inprocess)" in text


def test_the_table_of_a_realtime_run_claims_no_determinism(tmp_path: Path) -> None:
    with RunRecord(write(tmp_path, mode="realtime")) as rec:
        s = summarize(rec)
    s["determinism_lost_at_s"] = 12.5  # (a lockstep guess would be shown; realtime claims nothing)
    lines = {ln.split("│")[1].strip(): ln.split("│")[2].strip()
             for ln in table_text(s).splitlines() if ln.count("│") >= 3}
    assert lines["deterministic"] == "not claimed (realtime runs on wall time)"
    assert lines["determinism_lost_at_s"] == "12.5"


def test_a_process_that_refused_nothing_of_a_kind_adds_nothing() -> None:
    by_kind, by_process = distinct_intrusions([{"process": "agent-1", "kind": "command", "source": "x", "count": 0}])
    assert by_kind == {"command": 0} and by_process == {"agent-1": 0}


def test_the_table_has_a_header_folds_long_values_and_shows_every_row(tmp_path: Path) -> None:
    with RunRecord(write(tmp_path)) as rec:
        s = summarize(rec)
    s["converged"] = False  # (a run that did not converge reads "no")
    s["messages_rejected_by_process"] = {}
    s["intrusions_by_process"], s["intrusion_sources"] = {}, []
    long_value = "session-" + "0123456789" * 12
    s["world_overruns"] = long_value  # a field after determinism_lost_at_s (the world's extras come last)
    con = Console(width=70, record=True, color_system=None)
    con.print(render(s))
    text = con.export_text()
    header = next(ln for ln in text.splitlines() if "┃" in ln)
    assert [c.strip() for c in header.split("┃")[1:3]] == ["field", "value"]
    lines = {ln.split("│")[1].strip(): ln.split("│")[2].strip() for ln in text.splitlines() if ln.count("│") >= 3}
    assert lines["converged"] == "no" and lines["finished"] == "no"
    for empty in ("messages_rejected_by_process", "intrusions_by_process", "intrusion_sources"):
        assert empty not in lines
    assert "world_overruns" in lines  # shown, although determinism_lost_at_s (None) before it is not
    folded = "".join(ln.split("│")[2].strip() for ln in text.splitlines() if ln.count("│") >= 3
                     and (ln.split("│")[1].strip() in ("world_overruns", "")))
    assert long_value in folded  # folded over several lines, not cut
