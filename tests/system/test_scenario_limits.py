"""Scenario limits (reconswarm/scenario/limits.py): what the wire refuses is refused by `scenario check` first,
magnitudes that broke `sim` are refused, and the physics warnings fire where runs collide.

The wire's limits are reconswarm.net.wire.wire's; the bounds on scans and hulls are checked against the real
sensing (reconswarm.plant.sensing) and knowledge (reconswarm.paper.knowledge) code, message by message, and
the sizes the check computes against the wire's encoder, byte for byte.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from reconswarm.errors import BadInput
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.paper.events import Event, EventKind
from reconswarm.paper.knowledge import KnownObstacles
from reconswarm.plant.sensing import ContourField
from reconswarm.scenario import limits, wire_limits
from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import load, parse, warnings
from reconswarm.scenario.wire_limits import (
    MAX_AGENT_ID,
    MAX_OBSTACLES,
    MAX_PAYLOAD_BYTES,
    MAX_POINTS,
    MAX_STR,
    MAX_VERTICES,
)

pytestmark = pytest.mark.parallel  # (no launch, no router, no wall-clock bound: beside the unit tests)

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"
PAPER_TEXT = PAPER.read_text()
DIAMOND = "vertices_m = [[345.0, 0.0], [300.0, 45.0], [255.0, 0.0], [300.0, -45.0]]"


def sub(old: str, new: str, text: str = PAPER_TEXT) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


def refused(text: str, field: str) -> str:
    with pytest.raises(BadInput) as exc:
        parse(text, "/x/s.toml")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"/x/s.toml: {field}: "), msg
    return msg


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", *args], capture_output=True, text=True,
                          timeout=300, cwd=ROOT)


def grid_scenario(n: int, first_id: int = 1) -> str:
    """n agents of radius 1 on a 10 m grid (slots the same grid), no obstacles."""
    head = PAPER_TEXT[:PAPER_TEXT.index("[[agents]]")]
    side = math.ceil(math.sqrt(n))
    rows = [f"[[agents]]\nid = {first_id + i}\nstart_m = [{10.0 * (i % side)}, {10.0 * (i // side)}]\nradius_m = 1.0\n"
            f"offset_m = [{15.0 * (i % side)}, {15.0 * (i // side)}]\n" for i in range(n)]
    return head + "\n".join(rows)


# ------------------------------------------------------------------------------- what the wire refuses


def test_obstacle_id_longer_than_the_wire_allows_is_refused_by_check(tmp_path):
    """The issue's case: a 200-character obstacle id was accepted, and the wire dropped every scan."""
    f = tmp_path / "long-id.toml"
    f.write_text(sub('id = "diamond"', f'id = "{"d" * 200}"'))
    r = cli("scenario", "check", str(f))
    assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and f"{f}: obstacles[0].id: 200 characters" in lines[0], r.stderr
    assert str(MAX_STR) in lines[0] and "`reconswarm sim` has no wire" in lines[0]
    # sim has no wire: it takes the id (and `scenario check --sim` says so).
    r = cli("scenario", "check", "--sim", str(f))
    assert r.returncode == 0 and r.stdout.strip().endswith("for sim)"), r.stderr
    r = cli("sim", str(f), "-o", str(tmp_path / "run"), "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["convergence_time_s"] == 222.25


def test_obstacle_id_at_the_wire_limit_is_accepted_and_its_scans_decode():
    oid = "d" * MAX_STR
    s = parse(sub('id = "diamond"', f'id = "{oid}"'))
    field = ContourField.from_scenario(s)
    p = np.array([[300.0, 60.0]])
    _, qs = field.scan(p, s.planner.sensing_range_m, field.true_distances(p))
    assert qs.size > 0
    pts = tuple((float(x), float(y), field.ids[o])
                for (x, y), o in zip(field.samples[qs], field.owner[qs], strict=True))
    assert {pt[2] for pt in pts} == {oid}
    assert wire.scan_from_wire(wire.scan_to_wire(wire.Scan(1, 0, 0.0, pts))).points == pts
    refused(sub('id = "diamond"', f'id = "{"d" * (MAX_STR + 1)}"'), "obstacles[0].id")


def test_agent_ids_are_the_wires():
    top = MAX_AGENT_ID
    s = parse(sub("id = 10\n", f"id = {top}\n"))
    assert s.agents[-1].id == top
    assert Keys("paper").parse(Keys("paper").host(top, "state")) == ("host", top, "state")
    refused(sub("id = 10\n", f"id = {top + 1}\n"), "agents[9].id")
    refused(sub("id = 10\n", "id = -1\n"), "agents[9].id")


def test_agent_count_follows_the_truth_message_size():
    """Every robot's state travels in one truth message: a swarm whose message exceeds the wire's size is
    refused, one whose message fits is accepted (and its real message decodes)."""
    rng = np.random.default_rng(0)
    ok_n, big_n = 20_000, 25_000
    s = parse(grid_scenario(ok_n))
    assert len(s.agents) == ok_n
    cols = [tuple(rng.normal(0, 1e5, ok_n).tolist()) for _ in range(5)]
    truth = wire.truth_to_wire(wire.Truth(6000, 300.0, tuple(a.id for a in s.agents), *cols))
    assert wire.truth_from_wire(truth).ids[-1] == ok_n
    msg = refused(grid_scenario(big_n), "agents")
    assert "truth" in msg and f"{MAX_PAYLOAD_BYTES:,}" in msg
    assert len(parse(grid_scenario(big_n), wire=False).agents) == big_n  # no wire, no truth message
    cols = [tuple(rng.normal(0, 1e5, big_n).tolist()) for _ in range(5)]
    with pytest.raises(WireError):
        wire.truth_from_wire(wire.truth_to_wire(wire.Truth(6000, 300.0, tuple(range(1, big_n + 1)), *cols)))


LONGEST_KIND = max(EventKind, key=lambda k: len(k.value))


def worst_messages(s) -> dict[str, bytes]:
    """The largest message of each growing kind, built as the processes would and encoded by the wire."""
    ids = tuple(a.id for a in s.agents)
    n, a_max, f = len(ids), max(ids), 0.1
    k, t = round(s.meta.duration_s / s.meta.dt_s) + 1, s.meta.duration_s
    scan = {o.id: limits.scan_points_max(o, s.planner.sensing_range_m) for o in s.obstacles}
    hull = {o.id: limits.hull_vertices_max(o) for o in s.obstacles}
    pts = tuple(pt for o in s.obstacles for pt in ((f, f, o.id),) * scan[o.id])
    stats = {f"{j:0{MAX_STR}d}": f for j in range(wire_limits.MAX_STATS)}
    return {
        "truth": wire.truth_to_wire(wire.Truth(k, t, ids, *(((f,) * n,) * 5))),
        "clock": wire.clock_to_wire(wire.Clock(k, t, ids, wire.ClockMode.REALTIME, f, True,
                                               "r" * wire_limits.MAX_REASON, 2**53, stats)),
        "event": wire.event_to_wire(Event(t, LONGEST_KIND, (ids,), tuple((i,) for i in ids), a_max,
                                               "c" * MAX_STR, f, f, f)),
        "state": wire.state_to_wire(wire.State(a_max, k, t, f, f, f, f, f, wire.Scan(a_max, k, t, pts, tuple(
            (i, f, f) for i in ids if i != a_max)))),
        "obstacle set": wire.obstacles_to_wire(wire.ObstacleSet(a_max, k, 2**53, {
            o.id: ((f, f),) * hull[o.id] for o in s.obstacles})),
    }


@pytest.mark.parametrize("case", ["paper", "long-ids", "big-ids", "many-agents", "wide-sensing"])
def test_computed_sizes_are_the_encoders_byte_for_byte(case):
    """The loader computes message sizes from msgpack's rules (it may not import the wire, a layer above);
    here they are checked against the wire's own encoder, and the decoder accepts them."""
    text = {"paper": PAPER_TEXT,
            "long-ids": sub('id = "diamond"', f'id = "{"d" * MAX_STR}"',
                            sub('id = "hexagon"', 'id = "h' + "x" * 40 + '"')),
            "big-ids": sub("id = 10\n", f"id = {MAX_AGENT_ID}\n", sub("id = 9\n", "id = 70000\n")),
            "many-agents": grid_scenario(3000, first_id=100),
            "wide-sensing": sub("sensing_range_m = 40.0", "sensing_range_m = 700.0")}[case]
    s = parse(text)
    scan = {o.id: limits.scan_points_max(o, s.planner.sensing_range_m) for o in s.obstacles}
    hull = {o.id: limits.hull_vertices_max(o) for o in s.obstacles}
    computed = {what: size for _, what, size in limits.largest_messages(s, scan, hull)}
    encoded = worst_messages(s)
    # The check allows an event kind of MAX_STR characters (the kinds are a layer above it); the longest is shorter.
    slack = {"event": (MAX_STR + 2) - (len(LONGEST_KIND.value) + 1)}
    assert computed == {what: len(b) + slack.get(what, 0) for what, b in encoded.items()}
    decode = {"truth": wire.truth_from_wire, "clock": wire.clock_from_wire, "event": wire.event_from_wire,
              "state": wire.state_from_wire, "obstacle set": wire.obstacles_from_wire}
    for what, payload in encoded.items():  # every message of an accepted scenario passes the wire's checks
        decode[what](payload)


def test_more_obstacles_than_an_obstacle_set_carries_is_refused():
    n = MAX_OBSTACLES + 1
    def tri(k: int) -> str:  # a small triangle, 3 m apart from the next
        x, y = 2000.0 + 3 * (k % 100), 3.0 * (k // 100)
        return f'[[obstacles]]\nid = "o{k}"\nvertices_m = [[{x}, {y}], [{x + 1}, {y}], [{x}, {y + 1}]]'

    obs = "\n".join(tri(k) for k in range(n))
    text = PAPER_TEXT[:PAPER_TEXT.index("[[obstacles]]")] + obs
    msg = refused(text, "obstacles")
    assert f"{n} obstacles" in msg and str(MAX_OBSTACLES) in msg


def test_hull_with_more_vertices_than_the_wire_carries_is_refused():
    # A regular polygon of 2100 vertices, edges of 1.5 m (2 samples each): an agent's hull can keep two
    # samples per edge, 4200 > 4096 vertices.
    v = 2100
    rad = 1.5 / (2 * math.sin(math.pi / v))
    verts = ", ".join(f"[{300 + rad * math.cos(2 * math.pi * i / v)!r}, {rad * math.sin(2 * math.pi * i / v)!r}]"
                      for i in range(v))
    text = sub(DIAMOND, f"vertices_m = [{verts}]")  # (the limits come before where agents start)
    msg = refused(text, "obstacles[0].vertices_m")
    assert "4200" in msg and str(MAX_VERTICES) in msg


def test_scan_larger_than_the_wire_carries_is_refused():
    # A 45 km x 20 km diamond seen from 30 km: up to ~100,000 contour points in one scan.
    big = "vertices_m = [[400000.0, 0.0], [377500.0, 10000.0], [355000.0, 0.0], [377500.0, -10000.0]]"
    msg = refused(sub("sensing_range_m = 40.0", "sensing_range_m = 30000.0", sub(DIAMOND, big)),
                  "planner.sensing_range_m")
    assert str(MAX_POINTS) in msg


@pytest.mark.parametrize("sensing_range_m", [3.0, 40.0, 300.0])
def test_scan_and_hull_bounds_hold_for_the_real_sensing_and_knowledge(sensing_range_m):
    """Soundness of the bounds the check relies on: from head points all around the obstacles, every real
    scan (simworld's sensing) holds at most scan_points_max points and decodes; an agent's hull (agent's
    knowledge, merging scan after scan) has at most hull_vertices_max vertices, and its obstacle set decodes."""
    oid = "x" * MAX_STR
    text = sub('id = "diamond"', f'id = "{oid}"', sub("sensing_range_m = 40.0", f"sensing_range_m = {sensing_range_m}"))
    s = parse(text)
    field = ContourField.from_scenario(s)
    bound_scan = sum(limits.scan_points_max(o, sensing_range_m) for o in s.obstacles)
    bound_hull = {o.id: limits.hull_vertices_max(o) for o in s.obstacles}
    know = KnownObstacles()
    rng = np.random.default_rng(1)
    # Head points along every edge (on it, and at 0.3 R_v and 0.9 R_v outside), plus random ones.
    heads = []
    for poly in field.polygons:
        for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
            normal = np.array([b[1] - a[1], a[0] - b[0]]) / np.hypot(*(b - a))
            for t in np.linspace(0, 1, 25):
                for off in (0.0, 0.3 * sensing_range_m, 0.9 * sensing_range_m):
                    heads.append(a + t * (b - a) + off * normal)
    heads += list(rng.uniform([200, -150], [600, 150], (400, 2)))
    p = np.array(heads)
    qa, qs = field.scan(p, sensing_range_m, field.true_distances(p))
    counts = np.bincount(qa, minlength=p.shape[0])
    assert counts.max() > 0
    assert counts.max() <= bound_scan
    for i in np.argsort(counts)[-20:]:  # the largest scans, as simworld encodes them
        idx = qs[qa == i]
        pts = tuple(zip(*field.samples[idx].T.tolist(), [field.ids[o] for o in field.owner[idx].tolist()],
                        strict=True))
        assert len(wire.scan_from_wire(wire.scan_to_wire(wire.Scan(7, 6001, 300.0, pts))).points) == counts[i]
    for i in rng.permutation(p.shape[0]):  # one agent visiting every head point, in random order
        idx = qs[qa == i]
        for m in np.unique(field.owner[idx]):
            know.merge(field.ids[m], field.samples[idx[field.owner[idx] == m]])
    assert know.hulls
    for name, hull in know.hulls.items():
        assert hull.shape[0] <= bound_hull[name], (name, hull.shape[0], bound_hull[name])
    sets = {name: tuple(map(tuple, h.tolist())) for name, h in know.hulls.items()}
    assert wire.obstacles_from_wire(wire.obstacles_to_wire(wire.ObstacleSet(7, 6001, 99, sets))).obstacles == sets


def test_a_generated_100k_swarm_is_refused_only_by_the_wire():
    """The issue's case: 100,000 agents and 20 obstacles. The in-process engine's limits (memory, magnitudes)
    take it; only the wire, which `sim` does not use, refuses it (its truth message)."""
    s = generate(100_000, 20, 0)
    agent_path = {a.id: f"agents[{k}]" for k, a in enumerate(s.agents)}
    obstacle_path = {o.id: f"obstacles[{k}]" for k, o in enumerate(s.obstacles)}
    assert list(limits.problems(s, agent_path, obstacle_path)) == []
    wire_refusals = list(limits.wire_problems(s, obstacle_path))
    assert wire_refusals and wire_refusals[0][0] == "agents" and "truth" in wire_refusals[0][1]


# ----------------------------------------------------------------------- magnitudes that broke `sim`

# The cases: accepted by check, then a traceback (or robots at 4.6e14 m, or an OOM) in sim.
BROKE_SIM = [
    ("vertex-1e9", sub(DIAMOND, DIAMOND.replace("[345.0, 0.0]", "[1e9, 0.0]")), "obstacles[0].vertices_m[0][0]"),
    ("k_att-1e300", sub("k_att = 0.08", "k_att = 1e300"), "planner.k_att"),
    ("psi-1e308", sub("psi_mps = -65.0", "psi_mps = -1e308"), "planner.psi_mps"),
    ("stall-1e308", sub("converge_tol_m = 0.5", "converge_tol_m = 0.5\nstall_window_s = 1e308"),
     "planner.stall_window_s"),
    ("d_safe-2e-15-below-d_max", sub("d_safe_m = 2.0", "d_safe_m = 9.999999999999998"), "planner.d_safe_m"),
    ("contours-2900-km", sub(DIAMOND, "vertices_m = [[900000.0, 0.0], [300.0, 450000.0], [255.0, 0.0], "
                                      "[300.0, -450000.0]]"), "obstacles[0].vertices_m"),
    # (sim exited 1 with no word, robot 1 NaN from the first step, its rows missing from the export)
    ("head-offset-5e-324", sub("head_offset_m = 0.5", "head_offset_m = 5e-324"), "agents[0].head_offset_m"),
]


@pytest.mark.parametrize(("name", "text", "field"), BROKE_SIM, ids=[b[0] for b in BROKE_SIM])
def test_check_and_sim_refuse_what_broke_sim(tmp_path, name, text, field):
    f = tmp_path / f"{name}.toml"
    f.write_text(text)
    for args in (["scenario", "check", str(f)], ["sim", str(f), "-o", str(tmp_path / "run"), "--json"]):
        r = cli(*args)
        assert r.returncode == 2, (args, r.stderr)
        lines = r.stderr.splitlines()
        assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
        assert f"{f}: {field}: " in lines[0], lines[0]
        assert r.stdout == ""
    assert not (tmp_path / "run" / "run.db").exists()


def test_k_att_stability_limit_is_explicit_euler():
    # k_att dt < 2 accepted (the error shrinks by |1 - k_att dt| < 1 per step), 2 refused.
    s = parse(sub("k_att = 0.08", "k_att = 39.9"))
    assert abs(1 - s.planner.k_att * s.meta.dt_s) < 1
    refused(sub("k_att = 0.08", "k_att = 40.0"), "planner.k_att")


# ------------------------------------------------------------------------------------ physics warnings

# Accepted but unsafe: the runs collided (dt_s = 1: 7, sensing_range_m = 1e-300: 10, psi = -1e-300: 21).
UNSAFE = [
    ("dt-1", sub("dt_s = 0.05", "dt_s = 1.0"), "scenario.dt_s"),
    ("sensing-1e-300", sub("sensing_range_m = 40.0", "sensing_range_m = 1e-300"), "planner.sensing_range_m"),
    ("psi-1e-300", sub("psi_mps = -65.0", "psi_mps = -1e-300"), "planner.psi_mps"),
]


@pytest.mark.parametrize(("name", "text", "field"), UNSAFE, ids=[u[0] for u in UNSAFE])
def test_unsafe_physics_is_a_warning_from_check_and_sim_and_runs_do_collide(tmp_path, name, text, field):
    f = tmp_path / f"{name}.toml"
    f.write_text(text.replace("duration_s = 300.0", "duration_s = 120.0"))
    r = cli("scenario", "check", str(f))
    assert r.returncode == 0 and "ok" in r.stdout, r.stderr
    warns = [ln for ln in r.stderr.splitlines() if ln.startswith("warning: ")]
    assert len(warns) == 1 and f"{f}: {field}: " in warns[0] and "contacts likely" in warns[0], r.stderr
    r = cli("sim", str(f), "-o", str(tmp_path / "run"), "--json")
    assert "Traceback" not in r.stderr
    assert [ln for ln in r.stderr.splitlines() if ln.startswith("warning: ")] == warns
    summary = json.loads(r.stdout)
    assert summary["collisions"] > 0  # what the warning says: this run collides
    assert r.returncode == 1


def test_paper_scenario_has_no_warning_and_its_margins():
    s = load(PAPER)
    assert warnings(s) == [] and limits.physics_warnings(s) == []
    p, dt = s.planner, s.meta.dt_s
    v = p.target_radius_m * p.k_att
    assert v == pytest.approx(6.4)
    assert 2 * v * dt / (p.d_max_m - p.d_safe_m) == pytest.approx(0.08)  # closing step: 8 % of the band
    assert v / abs(p.psi_mps) < 0.1  # repulsion balances the approach 0.79 m into the 8 m band
