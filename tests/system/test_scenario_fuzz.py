"""Scenario fuzzing: a fixed table of mutations of deploy/scenarios/paper.toml (every number of the file,
26 fields x 14 values, plus the edge cases of the issue). Each mutation is either refused with one line
`FILE: field.path: what is wrong` naming the mutated field (or the one it is checked against), or runs the
mission (`sim`'s engine, the first SIM_S simulated seconds) without an exception and with finite positions;
and an accepted mutation without a physics warning runs without a collision.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from reconswarm.errors import BadInput
from reconswarm.limits import physics_warnings
from reconswarm.record.store import RunRecord
from reconswarm.scenario import parse, warnings
from reconswarm_bringup import engine

ROOT = Path(__file__).resolve().parents[2]
BASE = (ROOT / "deploy" / "scenarios" / "paper.toml").read_text().replace(
    "converge_tol_m = 0.5\n", "converge_tol_m = 0.5\nstall_window_s = 5.0\n")
SIM_S = 40.0  # simulated seconds per accepted mutation: the swarm reaches the diamond at t ~ 40 s

# field path -> regex whose group 1 is the value in BASE
FIELDS: dict[str, str] = {
    "scenario.seed": r"\nseed = (0)", "scenario.duration_s": r"duration_s = (300\.0)",
    "scenario.dt_s": r"dt_s = (0\.05)",
    **{f"planner.{k}": rf"\n{k} = ([-0-9.]+)" for k in (
        "k_att", "target_radius_m", "psi_mps", "d_safe_m", "d_max_m", "sensing_range_m", "link_range_m",
        "perturbation_mps", "converge_tol_m", "stall_window_s")},
    "world.max_speed_mps": r"max_speed_mps = (0\.0)", "world.max_turn_rate_radps": r"max_turn_rate_radps = (0\.0)",
    "target.center_m[0]": r"center_m = \[(800\.0), 0\.0\]", "target.center_m[1]": r"center_m = \[800\.0, (0\.0)\]",
    "agents[0].start_m[0]": r"start_m = \[(41\.3), 50\.5\]", "agents[0].start_m[1]": r"start_m = \[41\.3, (50\.5)\]",
    "agents[0].heading_rad": r"heading_rad = (0\.0)", "agents[0].radius_m": r"radius_m = (2\.60)",
    "agents[0].offset_m[0]": r"offset_m = \[(0\.0), 41\.57\]",
    "agents[0].offset_m[1]": r"offset_m = \[0\.0, (41\.57)\]",
    "agents[0].head_offset_m": r"head_offset_m = (0\.5)",
    "obstacles[0].vertices_m[0][0]": r"vertices_m = \[\[(345\.0), 0\.0\]",
    "obstacles[0].vertices_m[0][1]": r"vertices_m = \[\[345\.0, (0\.0)\]",
}
VALUES = ["0", "-0.0", "-1", "1e-300", "-1e-300", "1e-15", "1e15", "-1e15", "1e300", "-1e308", "1e308",
          "9223372036854775807", "inf", "nan"]
# A refusal may name the field the mutated one is checked against.
RELATED = {
    "scenario.dt_s": {"scenario.duration_s", "planner.stall_window_s"},
    "planner.d_safe_m": {"planner.d_max_m"}, "planner.d_max_m": {"planner.d_safe_m"},
    "obstacles[0].vertices_m[0][0]": {"obstacles[0].vertices_m"},
    "obstacles[0].vertices_m[0][1]": {"obstacles[0].vertices_m"},
}


def mutate(field: str, value: str, text: str = BASE) -> str:
    m = re.search(FIELDS[field], text)
    assert m, field
    return text[:m.start(1)] + value + text[m.end(1):]


CASES = [(f, v, mutate(f, v)) for f in FIELDS for v in VALUES] + [
    # The issue's cases and the edges of the new bounds.
    ("planner.d_safe_m", "9.999999999999998", mutate("planner.d_safe_m", "9.999999999999998")),
    ("planner.d_safe_m", "9.99", mutate("planner.d_safe_m", "9.99")),
    ("scenario.dt_s", "1.0", mutate("scenario.dt_s", "1.0")),
    ("scenario.dt_s", "0.5", mutate("scenario.dt_s", "0.5")),
    ("planner.k_att", "39.99", mutate("planner.k_att", "39.99")),
    ("planner.k_att", "40.0", mutate("planner.k_att", "40.0")),
    ("planner.psi_mps", "-12.0", mutate("planner.psi_mps", "-12.0")),
    ("planner.sensing_range_m", "12.0", mutate("planner.sensing_range_m", "12.0")),
    ("planner.stall_window_s", "1e308", mutate("planner.stall_window_s", "1e308")),
    ("obstacles[0].vertices_m[0][0]", "1e9", mutate("obstacles[0].vertices_m[0][0]", "1e9")),
    ("obstacles[0].vertices_m[0][0]", "999999.0", mutate("obstacles[0].vertices_m[0][0]", "999999.0")),
]


def test_the_table_is_the_size_of_the_issues():
    assert len(FIELDS) * len(VALUES) == 364 and len(CASES) == 375


@pytest.mark.parametrize(("field", "value", "text"), CASES, ids=[f"{c[0]}={c[1]}" for c in CASES])
def test_mutation_is_refused_naming_the_field_or_runs(tmp_path, field, value, text):
    src = f"{tmp_path}/mutant.toml"
    try:
        s = parse(text, src)
    except BadInput as exc:
        msg = str(exc)
        assert "\n" not in msg and msg.startswith(f"{src}: "), msg
        named = msg[len(src) + 2:].split(": ", 1)[0]
        assert named == field or named in RELATED.get(field, set()), msg
        assert exc.exit_code == 2
        return
    for w in warnings(s):
        assert "\n" not in w and w.startswith(f"{src}: ")
    short = replace(s, meta=replace(s.meta, duration_s=min(s.meta.duration_s, SIM_S)))
    summary = engine.run(engine.SimConfig(short, tmp_path, progress=False))  # no exception
    rec = RunRecord(tmp_path / "run.db")
    try:
        tk = rec.ticks()
    finally:
        rec.close()
    assert tk.t.size >= 1 and np.isfinite(tk.px).all() and np.isfinite(tk.py).all()
    if not physics_warnings(s):
        assert summary["collisions"] == 0, (field, value)
