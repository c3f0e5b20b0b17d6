"""Scenario files: strict validation (the whole table through the CLI in process), the TOML writer, the generator."""

from __future__ import annotations

import hashlib
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from reconswarm.errors import BadInput
from reconswarm.geometry.plane import is_strictly_convex, polygon_area
from reconswarm.scenario.generate import D_MAX_M, D_SAFE_M, R_MAX_M, SLOT_SPACING_M, START_SPACING_M, generate
from reconswarm.scenario.model import load, parse, to_toml, warnings

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"
PAPER_TEXT = PAPER.read_text()
def sub(old: str, new: str, text: str = PAPER_TEXT) -> str:
    assert text.count(old) >= 1, old
    return text.replace(old, new, 1)


def without_line(line: str) -> str:
    assert f"\n{line}\n" in PAPER_TEXT
    return PAPER_TEXT.replace(f"\n{line}\n", "\n", 1)


DIAMOND = "vertices_m = [[345.0, 0.0], [300.0, 45.0], [255.0, 0.0], [300.0, -45.0]]"

# (case id, mutated text, field path the one-line error must name)
BAD = [
    ("unknown-key", sub("k_att = 0.08", "k_att = 0.08\nk_rep = 1.0"), "planner.k_rep"),
    ("unknown-top-table", PAPER_TEXT + "\n[extras]\nx = 1\n", "extras"),
    ("unknown-agent-key", sub("head_offset_m = 0.5", "head_offset_m = 0.5\ncolour = 'red'"), "agents[0].colour"),
    ("missing-key", without_line("k_att = 0.08"), "planner.k_att"),
    ("missing-agent-key", sub("radius_m = 4.58\n", ""), "agents[1].radius_m"),
    ("missing-table", sub("[target]\ncenter_m = [800.0, 0.0]\n", ""), "target"),
    ("wrong-type", sub("dt_s = 0.05", 'dt_s = "0.05"'), "scenario.dt_s"),
    ("wrong-type-bool", sub("d_safe_m = 2.0", "d_safe_m = true"), "planner.d_safe_m"),
    ("wrong-type-point", sub("start_m = [41.3, 50.5]", 'start_m = [41.3, "50.5"]'), "agents[0].start_m[1]"),
    ("wrong-type-id", sub('id = "hexagon"', "id = 2"), "obstacles[1].id"),
    ("nan", sub("psi_mps = -65.0", "psi_mps = nan"), "planner.psi_mps"),
    ("inf", sub("duration_s = 300.0", "duration_s = inf"), "scenario.duration_s"),
    ("nan-vertex", sub(DIAMOND, DIAMOND.replace("[300.0, 45.0]", "[300.0, nan]")),
     "obstacles[0].vertices_m[1][1]"),
    ("-inf-start", sub("start_m = [19.2, 9.7]", "start_m = [19.2, -inf]"), "agents[1].start_m[1]"),
    ("duplicate-agent-id", sub("id = 2\n", "id = 1\n"), "agents[1].id"),
    ("duplicate-obstacle-id", sub('id = "hexagon"', 'id = "diamond"'), "obstacles[1].id"),
    ("non-convex", sub(DIAMOND, "vertices_m = [[345.0, 0.0], [300.0, 45.0], [310.0, 0.0], [300.0, -45.0]]"),
     "obstacles[0].vertices_m"),
    ("collinear-vertex", sub(DIAMOND, "vertices_m = [[345.0, 0.0], [322.5, 22.5], [300.0, 45.0], [255.0, 0.0], "
                                      "[300.0, -45.0]]"), "obstacles[0].vertices_m"),
    ("degenerate-collinear", sub(DIAMOND, "vertices_m = [[250.0, 0.0], [300.0, 0.0], [350.0, 0.0]]"),
     "obstacles[0].vertices_m"),
    ("degenerate-repeated-vertex", sub(DIAMOND, "vertices_m = [[345.0, 0.0], [300.0, 45.0], [300.0, 45.0], "
                                                "[255.0, 0.0], [300.0, -45.0]]"), "obstacles[0].vertices_m[2]"),
    ("too-few-vertices", sub(DIAMOND, "vertices_m = [[345.0, 0.0], [300.0, 45.0]]"), "obstacles[0].vertices_m"),
    ("agents-overlapping", sub("start_m = [19.2, 9.7]", "start_m = [43.0, 50.5]"), "agents[1].start_m"),
    ("agent-inside-obstacle", sub("start_m = [41.3, 50.5]", "start_m = [300.0, 0.0]"), "agents[0].start_m"),
    ("agent-touching-obstacle", sub("start_m = [41.3, 50.5]", "start_m = [346.0, 0.0]"), "agents[0].start_m"),
    ("psi-positive", sub("psi_mps = -65.0", "psi_mps = 65.0"), "planner.psi_mps"),
    ("psi-zero", sub("psi_mps = -65.0", "psi_mps = 0.0"), "planner.psi_mps"),
    ("d_max-below-d_safe", sub("d_max_m = 10.0", "d_max_m = 1.5"), "planner.d_max_m"),
    ("d_max-equals-d_safe", sub("d_max_m = 10.0", "d_max_m = 2.0"), "planner.d_max_m"),
    ("bad-planner-kind", sub('kind = "reconfigurable"', 'kind = "apf"'), "planner.kind"),
    ("negative-radius", sub("radius_m = 2.60", "radius_m = -2.60"), "agents[0].radius_m"),
    ("zero-dt", sub("dt_s = 0.05", "dt_s = 0.0"), "scenario.dt_s"),
    ("bad-name", sub('name = "paper"', 'name = "my paper"'), "scenario.name"),
    # Subnormal floats (nonzero, below 2.2e-308): a division or a square root of them is not finite.
    ("subnormal-head-offset", sub("head_offset_m = 0.5", "head_offset_m = 5e-324"), "agents[0].head_offset_m"),
    ("subnormal-radius", sub("radius_m = 2.60", "radius_m = 1e-310"), "agents[0].radius_m"),
    ("subnormal-dt", sub("dt_s = 0.05", "dt_s = 5e-324"), "scenario.dt_s"),
    ("subnormal-d_safe", sub("d_safe_m = 2.0", "d_safe_m = 1e-320"), "planner.d_safe_m"),
    ("subnormal-max-speed", sub("max_speed_mps = 0.0", "max_speed_mps = 5e-324"), "world.max_speed_mps"),
    ("subnormal-heading", sub("heading_rad = 0.0", "heading_rad = -5e-324"), "agents[0].heading_rad"),
    ("subnormal-start", sub("start_m = [41.3, 50.5]", "start_m = [41.3, 1e-310]"), "agents[0].start_m[1]"),
    # A normal head offset so small that the turn rate of the fastest step, |u| / head_offset_m, is not finite.
    ("tiny-head-offset", sub("head_offset_m = 0.5", "head_offset_m = 1e-302"), "agents[0].head_offset_m"),
]


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bad")
    out = {}
    for name, text, _ in BAD:
        f = d / f"{name}.toml"
        f.write_text(text)
        out[name] = f
    return out


@pytest.mark.parametrize(("name", "text", "field"), BAD, ids=[b[0] for b in BAD])
def test_parse_refuses_with_file_and_field(name, text, field):
    with pytest.raises(BadInput) as exc:
        parse(text, f"/x/{name}.toml")
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"/x/{name}.toml: {field}: "), msg
    assert exc.value.exit_code == 2


# One case of every kind the issue lists, each through a real process (the rest in process, below).
CHECK_IN_SUBPROCESS = ["unknown-key", "missing-key", "wrong-type", "nan", "inf", "duplicate-agent-id",
                       "duplicate-obstacle-id", "non-convex", "degenerate-collinear", "degenerate-repeated-vertex",
                       "agents-overlapping", "agent-inside-obstacle", "psi-positive", "d_max-below-d_safe",
                       "bad-planner-kind"]


@pytest.mark.parametrize("command", ["check", "sim"])
@pytest.mark.parametrize(("name", "field"), [(b[0], b[2]) for b in BAD], ids=[b[0] for b in BAD])
def test_cli_refuses_every_bad_file(bad_files, tmp_path, name, field, command):
    """The full table through the CLI in process (typer's runner: one import for every case)."""
    from typer.testing import CliRunner

    from reconswarm_bringup.cli import app

    out = tmp_path / "run"
    args = ["scenario", "check", str(bad_files[name])] if command == "check" else [
        "sim", str(bad_files[name]), "-o", str(out), "--json"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2, r.output
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    assert str(bad_files[name]) in lines[0] and f": {field}: " in lines[0]
    assert r.stdout == ""
    assert not (out / "run.db").exists()  # refused before anything ran


def test_clockwise_obstacle_is_normalised_to_ccw():
    s = parse(sub(DIAMOND, "vertices_m = [[300.0, -45.0], [255.0, 0.0], [300.0, 45.0], [345.0, 0.0]]"))
    assert polygon_area(s.polygon(0)) > 0
    assert s.polygon(0).tolist() == [[345.0, 0.0], [300.0, 45.0], [255.0, 0.0], [300.0, -45.0]]


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(BadInput, match=r"^/nonexistent/x\.toml: file not found$"):
        load("/nonexistent/x.toml")
    bad = tmp_path / "broken.toml"
    bad.write_text("[scenario\nname = 1\n")
    with pytest.raises(BadInput, match=rf"^{bad}: not valid TOML"):
        load(bad)


# ------------------------------------------------------------------------------------------ round trip


def test_to_toml_round_trip_paper():
    s = load(PAPER)
    text = to_toml(s)
    again = parse(text)
    assert again == s
    assert to_toml(again) == text
    # Optional fields written out and every float exactly preserved (repr).
    s2 = replace(s, meta=replace(s.meta, dt_s=0.1 + 0.2, seed=12345))
    assert parse(to_toml(s2)) == s2


# ------------------------------------------------------------------------------------------ generator


def assumption_4_1_holds(s) -> bool:
    off, r = s.offsets, s.radii
    d = np.sqrt(((off[:, None, :] - off[None, :, :]) ** 2).sum(-1))
    need = r[:, None] + r[None, :] + s.planner.d_max_m
    np.fill_diagonal(d, np.inf)
    return bool(np.all(d >= need))


@pytest.mark.parametrize(("n", "m", "seed"), [(1, 0, 0), (1, 3, 5), (10, 3, 0), (10, 0, 1), (10, 6, 2), (200, 3, 1),
                                              (200, 12, 7), (2000, 3, 3), (200, 22, 0), (10, 12, 4)])
def test_generated_scenarios_are_valid(n, m, seed):
    s = generate(n, m, seed)
    assert len(s.agents) == n and len(s.obstacles) == m
    text = to_toml(s)
    again = parse(text, "<gen>")
    assert again == s  # passes validation and round-trips
    assert to_toml(again) == text
    assert warnings(again) == []  # Assumptions 4.1 and 4.2 hold
    assert assumption_4_1_holds(s)
    slots = np.asarray(s.target_m) + s.offsets
    # Every slot lies well inside the target disk.
    assert np.all(np.hypot(*(slots - s.target_m).T) + s.radii <= s.planner.target_radius_m)
    polys = [Polygon(s.polygon(k)) for k in range(m)]
    for k, poly in enumerate(polys):
        assert is_strictly_convex(s.polygon(k)) and polygon_area(s.polygon(k)) > 0
        # Obstacles apart from each other by more than a robot and its safety band on both sides ...
        for j in range(k):
            assert poly.distance(polys[j]) > 2 * R_MAX_M + 2 * D_SAFE_M
        # ... and out of reach of every slot (Assumption 4.2).
        assert min(poly.distance(Point(*q)) - r for q, r in zip(slots, s.radii, strict=True)) >= D_MAX_M
    # Neighbouring slots leave a lane clear of both repulsion bands (eq. 11) for the largest robot, so an
    # agent that arrives after its neighbours have settled can pass between them ...
    if n > 1:
        d_slots = np.hypot(*(s.offsets[:, None, :] - s.offsets[None, :, :]).transpose(2, 0, 1))
        np.fill_diagonal(d_slots, np.inf)
        assert d_slots.min() / 2 >= 2 * R_MAX_M + s.planner.d_max_m
        # ... and each slot keeps its agent's place in the start lattice (the same lattice scaled up).
        lattice = s.offsets * (START_SPACING_M / SLOT_SPACING_M)
        assert np.abs(s.starts - lattice).max() <= 3.0 + 0.02
    # Deterministic in the seed; different seeds differ.
    assert generate(n, m, seed) == s
    if n > 1:
        assert generate(n, m, seed + 1) != s


def _digest(s) -> str:
    return hashlib.sha256(repr((s.target_m, s.meta, [o.vertices_m for o in s.obstacles],
                                [(a.start_m, a.offset_m, a.radius_m) for a in s.agents])).encode()).hexdigest()[:16]


def test_a_layout_the_corridor_holds_is_the_one_it_always_was_and_a_fuller_one_lengthens_the_corridor():
    """The corridor grows only when it cannot hold the obstacles asked for: the suites generated before (these
    digests) stay what they were; 22 obstacles for 200 agents (N / 10 + 2) fit in a longer corridor."""
    assert [_digest(generate(n, m, seed)) for n, m, seed in [(10, 3, 0), (40, 6, 7), (100, 12, 0), (200, 18, 1)]] == [
        "8e6841ccea7f784e", "6865b948d64f1c14", "0dad5a5dbeef4112", "36801d05cfb19b70"]
    held, fuller = generate(200, 18, 0), generate(200, 22, 0)
    assert len(fuller.obstacles) == 22 and fuller.target_m[0] > held.target_m[0]
    assert fuller.meta.duration_s > held.meta.duration_s  # (the longer way takes longer)
    with pytest.raises(RuntimeError, match="could not place 400 obstacles"):
        generate(10, 400, 0)


def test_generate_rejects_bad_sizes():
    with pytest.raises(ValueError):
        generate(0)
    with pytest.raises(ValueError):
        generate(3, -1)
    assert math.isfinite(generate(3, 0, 0).meta.duration_s)
