"""The run summary's counts from hand-made trajectories with known answers: the truth goes tick by tick through
the Recorder (safety episodes, the swarm graph's split / merge events, run.db) exactly as the engine and the
monitor feed it, and summarize reads the record back. Gaps are surface gaps: ‖p_i - p_j‖ - r_i - r_j and
dist(p_i, obstacle) - r_i; an episode is a maximal stretch below 0 (collision) or d_safe (safety); a grouping
of the swarm graph (link range 40 m) is an event once it has held 1 s."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from reconswarm.record.recorder import Recorder
from reconswarm.record.store import RunRecord, RunWriter
from reconswarm.record.summary import summarize
from reconswarm.scenario.model import parse

DT = 0.1
TOML = """
[scenario]
name = "hand-made"
seed = 0
duration_s = 20.0
dt_s = 0.1

[planner]
kind = "reconfigurable"
k_att = 0.08
target_radius_m = 30.0
psi_mps = -65.0
d_safe_m = 2.0
d_max_m = 10.0
sensing_range_m = 40.0
link_range_m = 40.0
perturbation_mps = 0.0
converge_tol_m = 0.5

[world]
max_speed_mps = 0.0
max_turn_rate_radps = 0.0

[target]
center_m = [0.0, 300.0]
""" + "".join(f"""
[[agents]]
id = {i}
start_m = [{x}, {y}]
heading_rad = 0.0
radius_m = 1.0
offset_m = [{5.0 * i}, 0.0]
head_offset_m = 0.5
""" for i, (x, y) in enumerate([(-0.5, 0.0), (9.5, 0.0), (44.5, 0.0), (9.5, 20.0)], start=1)) + """
[[obstacles]]
id = "box"
vertices_m = [[50.0, -5.0], [60.0, -5.0], [60.0, 5.0], [50.0, 5.0]]
"""
S = parse(TOML, "hand-made.toml")
HOME = np.array([[0.0, 0.0], [10.0, 0.0], [45.0, 0.0], [10.0, 20.0]])  # head points; radii 1 m


def record(tmp_path: Path, moves: dict[int, dict[range, tuple[float, float]]], ticks: int) -> dict:
    """Run the trajectory (agent index -> ticks -> head point, else HOME) through the Recorder; the summary."""
    writer = RunWriter(tmp_path / "run.db", S, "inprocess")
    rec = Recorder(S, writer)
    alive = np.ones(4, dtype=bool)
    for k in range(ticks):
        p = HOME.copy()
        for i, spans in moves.items():
            for span, xy in spans.items():
                if k in span:
                    p[i] = xy
        rec.tick(k, k * DT, p, np.zeros(4), alive)
    writer.close(finished="1")
    with RunRecord(tmp_path / "run.db") as r:
        s = summarize(r)
        s["_events"], s["_contacts"] = r.events(), r.contacts()
    return s


def test_nothing_close_nothing_moves_no_counts(tmp_path: Path) -> None:
    s = record(tmp_path, {}, 30)
    assert (s["collisions"], s["safety_violations"], s["splits"], s["merges"]) == (0, 0, 0, 0)
    # the closest pair: agents 1 and 2, 10 m apart; agent 3 is 5 m from the box
    assert s["min_agent_gap_m"] == pytest.approx(8.0) and s["min_obstacle_gap_m"] == pytest.approx(4.0)


def test_two_approaches_and_one_touch_of_the_obstacle(tmp_path: Path) -> None:
    agent2 = {  # agent 2 along the x axis toward agent 1 at the origin: gap = x - 2
        range(10, 13): (3.5, 0.0),  # 1.5 m: below d_safe (a safety episode starts at t = 1.0)
        range(13, 15): (1.5, 0.0),  # -0.5 m: a collision inside that episode (t = 1.3)
        range(15, 17): (3.5, 0.0),  # the collision ends, the safety episode goes on
        # 17..19 home (8 m): the episode ends
        range(20, 22): (1.8, 0.0),  # -0.2 m at once: a second safety episode and a second collision (t = 2.0)
        range(40, 41): (3.99, 0.0),  # 1.99 m: one tick below d_safe is an episode too (t = 4.0)
        range(45, 46): (4.0, 0.0),  # exactly d_safe: not below it
    }
    agent3 = {range(30, 32): (49.7, 0.0)}  # 0.3 m from the box: gap -0.7 m (t = 3.0)
    s = record(tmp_path, {1: agent2, 2: agent3}, 50)
    assert s["collisions"] == 3 and s["safety_violations"] == 4
    assert s["min_agent_gap_m"] == pytest.approx(-0.5) and s["min_obstacle_gap_m"] == pytest.approx(-0.7)
    got = sorted((c["kind"], c["a"], c["b"], round(c["t_start"], 6), round(c["t_end"], 6)) for c in s["_contacts"])
    assert got == sorted([
        ("safety", "agent:1", "agent:2", 1.0, 1.7), ("collision", "agent:1", "agent:2", 1.3, 1.5),
        ("safety", "agent:1", "agent:2", 2.0, 2.2), ("collision", "agent:1", "agent:2", 2.0, 2.2),
        ("safety", "agent:3", "obstacle:box", 3.0, 3.2), ("collision", "agent:3", "obstacle:box", 3.0, 3.2),
        ("safety", "agent:1", "agent:2", 4.0, 4.1),
    ])
    assert (s["splits"], s["merges"]) == (0, 0)


def test_an_agent_that_leaves_and_returns_is_one_split_and_one_merge(tmp_path: Path) -> None:
    agent4 = {
        range(40, 70): (10.0, 200.0),  # 180 m beyond everyone from t = 4.0 to 6.9: a split at 4.0
        # home from t = 7.0: a merge, confirmed at 8.0
        range(85, 90): (10.0, 200.0),  # away only 0.5 s (shorter than 1 s): no event
        range(95, 115): (10.0, 41.0),  # 2 s at 41 m from agent 2 (42.2 from 1): an existing link in its band
    }
    s = record(tmp_path, {3: agent4}, 120)
    assert (s["splits"], s["merges"]) == (1, 1)
    assert (s["collisions"], s["safety_violations"]) == (0, 0)
    split, merge = s["_events"]
    assert (split["t_confirmed"], merge["t_confirmed"]) == (pytest.approx(5.0), pytest.approx(8.0))
    assert (split["kind"], split["t"], split["before"], sorted(split["after"])) == (
        "split", pytest.approx(4.0), [[1, 2, 3, 4]], [[1, 2, 3], [4]])
    assert (merge["kind"], merge["t"], sorted(merge["before"]), merge["after"]) == (
        "merge", pytest.approx(7.0), [[1, 2, 3], [4]], [[1, 2, 3, 4]])
