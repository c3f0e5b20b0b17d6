"""Scenario fuzzing: a fixed table of mutations of deploy/scenarios/paper.toml (every number of the file,
26 fields x 14 values, plus the edge cases of the issue). Each mutation is either refused with one line
`FILE: field.path: what is wrong` naming the mutated field (or the one it is checked against), or runs the
mission (`sim`'s engine, the first SIM_S simulated seconds) without an exception and with finite positions.
Which it must be is decided by the documented rules (`expected`): a value they forbid must be refused, the
file's own value accepted. Whether a run must be contact-free is decided from the equations (docs/scenario.md's three
conditions and whether a world limit can bind, `contacts_likely`), not by the code's physics_warnings: a
run they call safe must have no collision, and one they do not must be warned of; a collision nobody
warned of fails too.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from reconswarm.errors import BadInput
from reconswarm.record.store import RunRecord
from reconswarm.scenario.limits import physics_warnings
from reconswarm.scenario.model import Scenario, parse, warnings
from reconswarm_bringup import engine

pytestmark = pytest.mark.parallel  # (no launch, no router, no wall-clock bound: beside the unit tests)

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
    # The cases and the edges of the new bounds.
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


# What the documented rules (docs/scenario.md) say of a value, decided here from the
# rules themselves and not by the code under test: REFUSE, ACCEPT (the file's own value again), or None
# (the rules do not decide: either a refusal naming the field or a run).
REFUSE, ACCEPT = "refuse", "accept"
BASE_VALUES = {f: re.search(rx, BASE).group(1) for f, rx in FIELDS.items()}  # type: ignore[union-attr]
LENGTHS = {"planner.target_radius_m", "planner.d_safe_m", "planner.d_max_m", "planner.sensing_range_m",
           "planner.link_range_m", "planner.converge_tol_m", "target.center_m[0]", "target.center_m[1]",
           "agents[0].start_m[0]", "agents[0].start_m[1]", "agents[0].radius_m", "agents[0].offset_m[0]",
           "agents[0].offset_m[1]", "agents[0].head_offset_m", "obstacles[0].vertices_m[0][0]",
           "obstacles[0].vertices_m[0][1]"}
POSITIVE = {"scenario.duration_s", "scenario.dt_s", "planner.k_att", "planner.target_radius_m",
            "planner.sensing_range_m", "planner.link_range_m", "planner.converge_tol_m", "planner.stall_window_s",
            "agents[0].radius_m", "agents[0].head_offset_m"}  # a step, a time, a gain, a size or a range > 0
NON_NEGATIVE = {"planner.d_safe_m", "planner.perturbation_mps", "world.max_speed_mps", "world.max_turn_rate_radps"}
SMALLEST_PAIR_M = 2.60 + 2.73  # the two smallest radii of paper.toml (agents 1 and 4)


def expected(field: str, value: str) -> str | None:
    if value in ("inf", "nan"):
        return REFUSE  # NaN/inf
    v = float(value)
    if field == "scenario.seed":
        return REFUSE if not re.fullmatch(r"-?[0-9]+", value) else None  # a float where an integer goes
    if v == float(BASE_VALUES[field]):
        return ACCEPT  # the paper's own file
    if (field in LENGTHS and abs(v) > 1e6) or (field == "agents[0].heading_rad" and abs(v) > 1000 * np.pi):
        return REFUSE  # coordinates and lengths beyond ±10^6 m, headings beyond ±1000π
    if (field in POSITIVE and not v > 0) or (field in NON_NEGATIVE and not v >= 0):
        return REFUSE
    dt = v if field == "scenario.dt_s" else 0.05
    k_att = v if field == "planner.k_att" else 0.08
    psi = v if field == "planner.psi_mps" else -65.0
    d_safe = v if field == "planner.d_safe_m" else 2.0
    d_max = v if field == "planner.d_max_m" else 10.0
    window = v if field == "planner.stall_window_s" else 5.0
    if psi >= 0 or d_max <= d_safe or k_att * dt >= 2:
        return REFUSE  # Ψ >= 0, d_max <= d_safe, explicit Euler on eq. 9 diverging
    if abs(psi) * dt * (SMALLEST_PAIR_M + d_max) / (d_max - d_safe) > 1e6:
        return REFUSE  # a repulsion step at contact beyond 10^6 m
    if window / dt * 8 > 2**30:
        return REFUSE  # a stall history (a float a tick) beyond 1 GiB
    return None


def _at(doc: object, path: str) -> tuple[object, object]:
    """(the container, the key or index) of a field path such as agents[0].start_m[1] in a parsed TOML."""
    parts = [int(p) if p.isdigit() else p for p in re.findall(r"[A-Za-z_]+|[0-9]+", path)]
    for p in parts[:-1]:
        doc = doc[p]  # type: ignore[index]
    return doc, parts[-1]


def _same(a: object, b: object) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def test_every_case_changes_exactly_the_field_it_names_to_its_value():
    """The table means what it says: each mutated file, read as TOML, differs from paper.toml in the named
    field alone, which holds the case's value (a pattern's first match is the named field's)."""
    base = tomllib.loads(BASE)
    for field, value, text in CASES:
        doc = tomllib.loads(text)
        holder, key = _at(doc, field)
        want = tomllib.loads(f"x = {value}")["x"]
        assert _same(holder[key], want) and type(holder[key]) is type(want), (field, value)  # type: ignore[index]
        holder[key] = _at(base, field)[0][_at(base, field)[1]]  # type: ignore[index]
        assert doc == base, (field, value)
    refused = sum(expected(f, v) == REFUSE for f, v, _ in CASES)
    assert refused > 0 and any(expected(f, v) == ACCEPT for f, v, _ in CASES)


def contacts_likely(s: Scenario) -> bool:
    """docs/scenario.md (Warnings), from eqs. 9 and 11: with v = R_c k_att + perturbation and the band w = d_max -
    d_safe, contacts are likely unless two agents closing 2 v dt per step stay within half the band, |Ψ| >=
    2 v, and R_v >= hypot(r + d_max + v dt, 0.5 m) for every radius r; or when a world limit can hold a robot
    back from its commands (below the largest |u| of eq. 7, attraction plus every term's contact push, or
    below that |u| over the smallest head offset for the turn rate: ω = |u⊥| / l, eq. 3)."""
    return not _paper_conditions(s) or limits_bind(s)


def _paper_conditions(s: Scenario) -> bool:
    p = s.planner
    v = p.target_radius_m * p.k_att + p.perturbation_mps
    w, dt = p.d_max_m - p.d_safe_m, s.meta.dt_s
    see = math.hypot(float(s.radii.max()) + p.d_max_m + v * dt, 0.5)
    return 2 * v * dt <= w / 2 and abs(p.psi_mps) >= 2 * v and p.sensing_range_m >= see


def limits_bind(s: Scenario) -> bool:
    p, world = s.planner, s.world
    u_max = (p.k_att * (p.target_radius_m + max(math.hypot(*o) for o in s.offsets)) + p.perturbation_mps
             + abs(p.psi_mps) * p.d_max_m / (p.d_max_m - p.d_safe_m) * (len(s.agents) - 1 + len(s.obstacles)))
    return (0 < world.max_speed_mps < u_max) or (0 < world.max_turn_rate_radps < u_max / float(s.head_offsets.min()))


@pytest.mark.parametrize(("field", "value", "text"), CASES, ids=[f"{c[0]}={c[1]}" for c in CASES])
def test_mutation_is_refused_naming_the_field_or_runs(tmp_path, field, value, text):
    src = f"{tmp_path}/mutant.toml"
    verdict = expected(field, value)
    try:
        s = parse(text, src)
    except BadInput as exc:
        msg = str(exc)
        assert verdict != ACCEPT, msg
        assert "\n" not in msg and msg.startswith(f"{src}: "), msg
        named = msg[len(src) + 2:].split(": ", 1)[0]
        assert named == field or named in RELATED.get(field, set()), msg
        assert exc.exit_code == 2
        return
    assert verdict != REFUSE, f"{field} = {value} was accepted"
    for w in warnings(s):
        assert "\n" not in w and w.startswith(f"{src}: ")
    likely = contacts_likely(s)
    if not _paper_conditions(s):
        assert physics_warnings(s), f"{field} = {value}: the equations say contacts are likely and nothing warns"
    short = replace(s, meta=replace(s.meta, duration_s=min(s.meta.duration_s, SIM_S)))
    summary = engine.run(engine.SimConfig(short, tmp_path, progress=False))  # no exception
    rec = RunRecord(tmp_path / "run.db")
    try:
        tk = rec.ticks()
    finally:
        rec.close()
    assert tk.t.size >= 1 and np.isfinite(tk.px).all() and np.isfinite(tk.py).all()
    if not likely:  # the equations say the run is contact-free: it must be, whatever the code warns
        assert summary["collisions"] == 0, (field, value)
    if summary["collisions"]:  # a collision the code did not warn of is a failure too
        assert physics_warnings(s), (field, value, summary["collisions"])
