"""Admission rules (reconswarm/net/trust/admission.py) against the attacks of issue 11 and against what the run
really sends (real commands, real shared hulls, the world's real clock): the attacks are refused with the
right kind, the run's own messages are all admitted."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest

from reconswarm.geometry.pairs import pairs_within
from reconswarm.geometry.plane import convex_hull, norm2
from reconswarm.net.timing import Timing
from reconswarm.net.trust.admission import (
    UNATTRIBUTED,
    Admission,
    Intrusion,
    IntrusionKind,
    command_bound_mps,
)
from reconswarm.net.trust.membership import Membership, Policy
from reconswarm.net.trust.tally import IntrusionTally
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.paper.planner import command, neighbour_table
from reconswarm.plant.sensing import ContourField
from reconswarm.scenario.model import load
from tests.support import PAPER, view_of

S = load(PAPER)
KEYS = Keys("paper-0a1b2c")
WORLD, A2, A5, X = "world-zid", "agent2-zid", "agent5-zid", "intruder-zid"
K = IntrusionKind


def kind(i: Intrusion | None) -> IntrusionKind | None:
    return None if i is None else i.kind


def beacon(aid: int, px: float, py: float, t: float = 10.0, radius: float | None = None) -> wire.Beacon:
    r = radius if radius is not None else S.radii[S.agent_index(aid)]
    return wire.Beacon(aid, round(t / S.meta.dt_s), t, px, py, float(r))


def clock(k: int, **kw: object) -> wire.Clock:
    return wire.Clock(k, k * S.meta.dt_s, tuple(a.id for a in S.agents), **kw)  # type: ignore[arg-type]


def started() -> Admission:
    adm = Admission(S)
    assert adm.check_clock(clock(0), WORLD, KEYS.clock) is None  # pins the world
    assert adm.check_beacon(beacon(2, 40.0, 0.0), A2, KEYS.host_beacons((0, 0), 2), now=0.0) is None  # pins agent 2
    assert adm.check_cmd(wire.Cmd(2, 0, 1.0, 0.0), A2, KEYS.host(2, "cmd"), now=0.0, world_k=0) is None
    return adm


def test_forged_cmd_for_agent_2_is_refused() -> None:
    adm = started()
    # Steering agent 2 into agent 5: a plausible command, but not from agent 2's session.
    steer = wire.Cmd(2, 1, -5.0, 3.0)
    got = adm.check_cmd(steer, X, KEYS.host(2, "cmd"), now=0.1, world_k=1)
    assert kind(got) is K.IMPERSONATION and got is not None and got.source == X and got.key == KEYS.host(2, "cmd")
    assert adm.check_cmd(steer, A2, KEYS.host(2, "cmd"), now=0.1, world_k=1) is None  # the real agent 2 is fine
    assert kind(adm.check_cmd(steer, UNATTRIBUTED, KEYS.host(2, "cmd"), now=0.1, world_k=1)) is K.IMPERSONATION
    # Whoever sends it: no command above what the planner can output, none for a tick not yet published.
    big = adm.u_max * 1.01
    assert kind(adm.check_cmd(wire.Cmd(2, 1, big, 0.0), A2, KEYS.host(2, "cmd"), 0.1, 1)) is K.COMMAND
    assert kind(adm.check_cmd(wire.Cmd(2, 9, 1.0, 0.0), A2, KEYS.host(2, "cmd"), 0.1, 1)) is K.COMMAND
    # A restarted agent's new session takes over once the old one has been silent for repin_after_s.
    assert kind(adm.check_cmd(steer, "agent2-new", KEYS.host(2, "cmd"), now=0.5, world_k=1)) is K.IMPERSONATION
    assert adm.check_cmd(steer, "agent2-new", KEYS.host(2, "cmd"), now=1.2, world_k=1) is None


def test_phantom_beacons_are_refused() -> None:
    adm = started()
    got = adm.check_beacon(beacon(99, 100.0, 0.0, radius=1e6), X, KEYS.host_beacons((0, 0), 99), now=1.0)
    assert kind(got) is K.UNKNOWN_AGENT
    got = adm.check_beacon(beacon(3, 100.0, 0.0, radius=1e6), X, KEYS.host_beacons((0, 0), 3), now=1.0)
    assert kind(got) is K.RADIUS
    # A phantom 60 m ahead of the swarm: an unknown id, or a real one from another session.
    got = adm.check_beacon(beacon(99, 100.0, 0.0, radius=2.6), X, KEYS.host_beacons((0, 0), 99), now=1.0)
    assert kind(got) is K.UNKNOWN_AGENT
    got = adm.check_beacon(beacon(2, 100.0, 0.0, t=12.0), X, KEYS.host_beacons((0, 0), 2), now=0.5)
    assert kind(got) is K.IMPERSONATION
    # Impossible positions: 1,000 km away at t = 10 s; a jump no robot can make between two beacons.
    assert kind(adm.check_beacon(beacon(5, 1e6, 0.0), A5, KEYS.host_beacons((0, 0), 5), now=1.0)) is K.POSITION
    assert adm.check_beacon(beacon(5, 40.0, 20.0, t=10.0), A5, KEYS.host_beacons((0, 0), 5), now=1.0) is None
    jump = adm.reach_m(0.05) + 1.0
    got = adm.check_beacon(beacon(5, 40.0 + jump, 20.0, t=10.05), A5, KEYS.host_beacons((0, 0), 5), now=1.1)
    assert kind(got) is K.POSITION


def _sensed_hull(field: ContourField, m: int, p: np.ndarray, rv: float) -> np.ndarray:
    block = field.samples[field.start[m]:field.start[m] + field.count[m]]
    seen = block[norm2(block - p) <= rv]
    return convex_hull(seen)


def test_hulls_must_lie_on_the_true_obstacle() -> None:
    adm = started()
    field = ContourField.from_scenario(S)
    rng = np.random.default_rng(0)
    admitted = 0
    for m, oid in enumerate(field.ids):  # what agents really share: hulls of sensed contour points, merged
        poly = field.polygons[m]
        hull = np.zeros((0, 2))
        for _ in range(20):
            p = poly.mean(axis=0) + rng.uniform(-80.0, 80.0, 2)
            seen = _sensed_hull(field, m, p, S.planner.sensing_range_m)
            if seen.shape[0]:
                hull = convex_hull(np.concatenate([hull, seen]))
                o = wire.ObstacleSet(2, 1, 1, {oid: tuple((float(x), float(y)) for x, y in hull)})
                assert adm.check_obstacles(o, X, KEYS.obstacles((0, 0), 2)) is None  # whoever sends the truth
                admitted += 1
    assert admitted > 20
    oid = field.ids[0]
    x0, y0 = field.polygons[0].mean(axis=0)
    slab = ((x0, y0 - 5.0), (x0 + 10_000.0, y0 - 5.0), (x0 + 10_000.0, y0 + 5.0), (x0, y0 + 5.0))
    got = adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {oid: slab}), X, KEYS.obstacles((0, 0), 2))
    assert kind(got) is K.HULL and got is not None and "off the obstacle's boundary" in got.detail
    # The same slab from the phantom: refused for its id already.
    got = adm.check_obstacles(wire.ObstacleSet(99, 1, 1, {oid: slab}), X, KEYS.obstacles((0, 0), 99))
    assert kind(got) is K.UNKNOWN_AGENT
    # More vertices than the sensor can produce on that obstacle (all on its boundary).
    edge = field.polygons[0][:2]
    line = edge[0] + np.linspace(0, 1, adm.max_vertices[oid] + 1)[:, None] * (edge[1] - edge[0])
    many = tuple((float(x), float(y)) for x, y in line)
    assert kind(adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {oid: many}), X, KEYS.obstacles((0, 0), 2))) is K.HULL


def test_a_hull_checked_once_is_remembered_and_a_bad_one_never_is() -> None:
    """Peers share the same merged hulls again and again: a hull found on the boundary is not measured
    again, a refused one is refused every time (it is never remembered), and the memory stays bounded."""
    adm = Admission(S, hull_vertices_kept=50)
    field = ContourField.from_scenario(S)
    oid, poly = field.ids[0], field.polygons[0]
    good = tuple((float(x), float(y)) for x, y in poly[:3])
    x0, y0 = poly.mean(axis=0)
    off = ((float(x0), float(y0)), *good[1:])  # one vertex at the obstacle's centre, off its boundary
    key = KEYS.obstacles((0, 0), 2)
    for _ in range(3):
        assert adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {oid: good}), A2, key) is None
        assert kind(adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {oid: off}), A2, key)) is K.HULL
    assert (oid, good) in adm.hulls_ok and (oid, off) not in adm.hulls_ok
    edge = poly[:2]
    n = 50 // 2 + 5
    for i in range(n):  # distinct truthful hulls: two points on one edge
        a = edge[0] + (i + 1) / (n + 5) * (edge[1] - edge[0])
        hull = ((float(edge[0][0]), float(edge[0][1])), (float(a[0]), float(a[1])))
        assert adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {oid: hull}), A2, key) is None
        assert sum(len(h) for _, h in adm.hulls_ok) <= 50
    assert len(adm.hulls_ok) < n


def test_an_obstacle_set_with_4000_ids_is_refused() -> None:
    adm = started()
    tri: tuple[tuple[float, float], ...] = ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))
    flood = {f"o{i}": tri for i in range(4000)}
    got = adm.check_obstacles(wire.ObstacleSet(2, 1, 1, flood), A2, KEYS.obstacles((0, 0), 2))
    assert kind(got) is K.UNKNOWN_OBSTACLE and got is not None and "4000 obstacle id(s)" in got.detail


def test_clock_only_from_the_world() -> None:
    adm = started()
    spoof = clock(7, end=True, reason="converged")
    got = adm.check_clock(spoof, X, KEYS.clock)
    assert kind(got) is K.NOT_FROM_WORLD and got is not None and "converged" in got.detail
    assert kind(adm.check_clock(spoof, UNATTRIBUTED, KEYS.clock)) is K.NOT_FROM_WORLD
    # A clock switching to realtime, even from the world's own session id: the run's mode does not change.
    got = adm.check_clock(clock(8, mode=wire.ClockMode.REALTIME, speed=10.0), WORLD, KEYS.clock)
    assert kind(got) is K.CLOCK
    assert kind(adm.check_clock(wire.Clock(9, 123.0, ()), WORLD, KEYS.clock)) is K.CLOCK  # t != k dt
    assert adm.check_clock(clock(9, end=True, reason="converged"), WORLD, KEYS.clock) is None
    # State, scan and truth likewise come from the world alone.
    assert adm.check_world_source(WORLD, KEYS.host(2, "state")) is None
    assert kind(adm.check_world_source(X, KEYS.host(2, "state"))) is K.NOT_FROM_WORLD
    fresh = Admission(S)  # the first message only the world sends pins the world's session, whichever it is
    assert fresh.check_world_source(WORLD, KEYS.host(2, "state")) is None
    assert kind(fresh.check_clock(clock(0), X, KEYS.clock)) is K.NOT_FROM_WORLD
    assert kind(Admission(S).check_world_source(UNATTRIBUTED, KEYS.host(2, "state"))) is K.NOT_FROM_WORLD


def test_a_forged_liveliness_token_does_not_keep_a_dead_agent_alive() -> None:
    m = Membership(Policy.world(Timing(token_confirm_s=0.0)))  # fresh 2 s / 2 s, grace 10 s / 5 s
    for a in (3, 4):
        m.token(a, True, 0.0, 0.0)
    assert m.alive_ids(0.5, 0.0) == [3, 4]  # before the start, tokens are enough
    m.start(1.0, 0.0)
    # wall and simulated time run together here (sim = 2 x wall - 2)
    for w in np.arange(1.0, 20.0, 0.5):
        m.data(3, float(w), 2 * float(w) - 2)
        m.data(4, float(w), 2 * float(w) - 2)
    # Agent 3 is killed at wall 20; an intruder's token for agent 3 stays (no token event ever comes).
    for w in np.arange(20.0, 30.0, 0.5):
        m.data(4, float(w), 2 * float(w) - 2)
    assert m.alive(3, 20.0, 38.0)
    assert not m.alive(3, 21.6, 41.2)  # silent 2.1 s of wall and 4.2 s simulated: dead
    assert m.alive_ids(30.0, 58.0) == [4]
    # A stalled world: nobody sends and simulated time stands still, however long: nobody dies of it.
    assert m.alive(4, 29.5 + 60.0, 57.0)
    # A fast realtime clock: 4 s simulated in 0.4 s of wall time is no death either.
    assert m.alive(4, 29.9, 61.0)
    # A token with no data at all after the start counts only for the grace period.
    m.token(99, True, 30.0, 58.0)
    assert m.alive(99, 39.0, 62.0) and not m.alive(99, 40.5, 63.5)
    m.token(4, False, 30.0, 58.0)  # a token gone: gone, whatever the data
    assert not m.alive(4, 30.0, 58.0)


def test_after_the_callers_own_stall_a_token_that_goes_is_kept_until_settled() -> None:
    """The world was frozen 10 s: its session lapsed, and every agent's token goes and comes back once it runs
    again. Nobody is gone for that; a token still gone once settled is."""
    m = Membership(Policy.world(Timing(token_confirm_s=0.0)))  # fresh 2 s / 2 s, grace 10 s / 5 s
    for a in (3, 4):
        m.token(a, True, 0.0, 0.0)
    m.start(1.0, 0.0)
    for a in (3, 4):
        m.data(a, 10.0, 20.0)
    m.settle(until_wall=23.0)  # (at wall 20, after 10 s without running; simulated time stood still)
    m.token(3, False, 20.1, 20.0)
    m.token(4, False, 20.1, 20.0)
    assert m.alive(3, 20.2, 20.0) and m.alive(4, 20.2, 20.0)  # kept while settling
    m.token(3, True, 20.3, 20.0)  # 3's token is back; 4's is not (its agent died meanwhile)
    assert m.alive(3, 22.9, 20.0) and m.alive(4, 22.9, 20.0)
    assert m.alive(3, 23.0, 20.0) and not m.alive(4, 23.0, 20.0)  # settled: 4 is gone
    assert m.alive_ids(23.0, 20.0) == [3]
    m.token(3, False, 24.0, 20.0)  # after settling, a token that goes is gone at once
    assert not m.alive(3, 24.0, 20.0)


def _contact_push_mps(psi: float, d_safe: float, d_max: float) -> float:
    """Eq. (11) at contact, from the equation: with D_max = r_i + r_j + d_max, D_min = r_i + r_j + d_safe and
    the push held below contact (D = r_i + r_j), |Ψ| (D_max - (r_i + r_j)) / (D_max - D_min) = |Ψ| d_max /
    (d_max - d_safe), whatever the radii (an obstacle: r_j = 0)."""
    return abs(psi) * d_max / (d_max - d_safe)


def _in_line_behind(i: int, at: np.ndarray, e: np.ndarray, n: int) -> np.ndarray:
    """Agent i at `at`, every other agent on the ray from it along e at 0.1..0.9 m: all overlap agent i
    (radii above 2 m), all in one direction, none on top of another."""
    p = np.zeros((n, 2))
    p[i] = at
    others = [j for j in range(n) if j != i]
    for m, j in enumerate(others):
        p[j] = at + (0.1 + 0.8 * m / max(1, len(others) - 1)) * e
    return p


def test_repulsion_in_contact_is_the_contact_push_whatever_the_overlap() -> None:
    """Every other agent overlapping agent i (by several metres), all on one side, obstacles and slot far
    away: u_i is eq. (9)'s attraction (outside B(p*, R_c): R_c k_att toward p*) plus (N - 1) contact pushes
    straight away from them, exactly; without the contact cap each push would grow with the overlap."""
    s, cfg, n = S, S.planner, len(S.agents)
    c = _contact_push_mps(cfg.psi_mps, cfg.d_safe_m, cfg.d_max_m)
    polys = [s.polygon(k) for k in range(len(s.obstacles))]
    target = np.array(s.target_m)
    for i in range(n):
        for ang in (0.0, 1.0, 2.5, -2.0):
            e = np.array([math.cos(ang), math.sin(ang)])
            at = np.array([100.0, -30.0 + 5.0 * i])  # 155 m from the nearest obstacle, 700 m from p*
            p = _in_line_behind(i, at, e, n)
            nb = neighbour_table(p, s.radii, pairs_within(p, 1e9), cfg.d_max_m)
            ob = view_of(p, n, len(polys), [(a, j, polys[j]) for a in range(n) for j in range(len(polys))])
            u = command(cfg, p, s.radii, s.offsets, target, nb, ob, np.zeros((n, 2)))
            to_target = (target - p[i]) / np.hypot(*(target - p[i]))
            expected = cfg.k_att * cfg.target_radius_m * to_target - (n - 1) * c * e
            np.testing.assert_allclose(u[i], expected, rtol=0, atol=1e-9)


def test_command_bound_holds_for_the_planner_even_in_contact() -> None:
    """|u| of eq. (7) with every agent and obstacle repelling at once stays below the bound from the
    equations: attraction at most k_att (R_c + max |Δ_i|) (eq. 9), each of the N - 1 agents' and M obstacles'
    terms at most its contact push (eq. 11 held at contact). Configurations include every other agent
    overlapping one agent from one side, where the pushes add up in one direction: without the contact cap
    they would exceed the bound."""
    s, rng = S, np.random.default_rng(1)
    cfg, n = s.planner, len(s.agents)
    c = _contact_push_mps(cfg.psi_mps, cfg.d_safe_m, cfg.d_max_m)
    bound = cfg.k_att * (cfg.target_radius_m + max(math.hypot(*o) for o in s.offsets)) + c * (n - 1 + len(s.obstacles))
    assert command_bound_mps(s) == pytest.approx(bound)  # what admission refuses above
    worst = 0.0
    polys = [s.polygon(k) for k in range(len(s.obstacles))]
    for trial in range(300):
        centre = polys[trial % len(polys)].mean(axis=0)
        if trial % 3 == 2:  # every other agent pressed into one, from one side, next to an obstacle
            e = rng.normal(size=2)
            p = _in_line_behind(trial % n, centre + rng.uniform(-20.0, 20.0, 2), e / np.hypot(*e), n)
        else:
            p = centre + rng.uniform(-15.0, 15.0, (n, 2)) * (1.0 if trial % 3 else 100.0)  # crowded, in contact
        nb = neighbour_table(p, s.radii, pairs_within(p, 1e9), cfg.d_max_m)
        ob = view_of(p, n, len(polys), [(i, j, polys[j]) for i in range(n) for j in range(len(polys))])
        u = command(cfg, p, s.radii, s.offsets, np.array(s.target_m), nb, ob, np.zeros((n, 2)))
        worst = max(worst, float(norm2(u).max()))
    assert worst <= bound
    assert worst >= (n - 1) * c - cfg.k_att * cfg.target_radius_m  # the aligned pushes were reached
    print(f"largest |u| in 300 crowded configurations: {worst:.1f} m/s (bound {bound:.1f})")


def test_tally_counts_per_kind_and_source() -> None:
    tally = IntrusionTally(max_rows=3)
    i1 = Intrusion(K.COMMAND, X, KEYS.host(2, "cmd"), "x")
    assert tally.add(i1, 1.0) and not tally.add(i1, 2.0)
    assert tally.add(Intrusion(K.CLOCK, X, KEYS.clock, "y"), 3.0)
    for n in range(5):  # an attacker cycling session ids fills no more than max_rows rows
        tally.add(Intrusion(K.COMMAND, f"s{n}", KEYS.host(2, "cmd"), "z"), 4.0 + n)
    assert tally.total == 8 and len(tally.rows) == 4
    assert ("command", X, 2, 1.0) in tally.as_rows() and ("command", "(other sources)", 4, 5.0) in tally.as_rows()


def test_report_round_trip_and_key() -> None:
    from reconswarm.net.wire.report import Report, report_from_wire, report_to_wire

    tally = IntrusionTally()
    tally.add(Intrusion(K.COMMAND, X, KEYS.host(2, "cmd"), "x"), 1.5)
    m = Report("agent-3", tuple(tally.as_rows()))
    assert report_from_wire(report_to_wire(m), "agent-3") == m
    with pytest.raises(WireError):
        report_from_wire(report_to_wire(m), "agent-4")  # another process's key
    with pytest.raises(WireError):
        report_from_wire(report_to_wire(Report("simworld", (("k", "s", -1, 0.0),))))
    beat = Report("agent-3", None, 7, 412)  # a heartbeat: counters, the tally unchanged (no rows)
    assert report_from_wire(report_to_wire(beat), "agent-3") == beat
    assert "rows" not in msgpack.unpackb(report_to_wire(beat))
    for field, bad_value in (("rejected", -1), ("guessed_k", -2), ("guessed_k", 1.5), ("rows", "x")):
        raw = msgpack.unpackb(report_to_wire(beat))
        raw[field] = bad_value
        with pytest.raises(WireError, match=field):
            report_from_wire(msgpack.packb(raw), "agent-3")
    assert KEYS.parse(KEYS.report("agent-3")) == ("report", 3, "agent-3")
    assert KEYS.parse(KEYS.report("simworld")) == ("report", None, "simworld")
    for bad in ("monitor", "agent-x", "agent-1/x"):
        with pytest.raises(WireError):
            KEYS.parse(KEYS.report(bad))


def test_gate_delivers_the_runs_messages_and_counts_logs_and_reports_the_rest(caplog: pytest.LogCaptureFixture) -> None:
    from reconswarm.net.trust.gate import Gate

    g = Gate(S, "agent-3")
    assert g.admit(clock(0), WORLD, KEYS.clock, 0.0) and g.world_k == 0
    assert g.admit(wire.State(3, 0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0), WORLD, KEYS.host(3, "state"), 0.0)
    assert g.admit(beacon(2, 40.0, 0.0, t=0.0), A2, KEYS.host_beacons((0, 0), 2), 0.0)
    assert g.report(0.0) is None  # nothing refused yet
    with caplog.at_level("WARNING", logger="reconswarm.admission"):
        assert not g.admit(wire.State(3, 1, 0.05, 9.0, 9.0, 0.0, 9.5, 9.0), X, KEYS.host(3, "state"), 0.1)
        for n in range(5):
            assert not g.admit(clock(2 + n, end=True, reason="converged"), X, KEYS.clock, 0.2 + 0.01 * n)
        assert not g.admit(beacon(99, 40.0, 0.0, t=0.0, radius=2.0), X, KEYS.host_beacons((0, 0), 99), 0.3)
    assert g.count == 7 and g.world_k == 0  # the spoofed clocks did not advance the world's tick
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and all(X in ln for ln in lines)  # first of each (kind, source) at once, rest quiet
    r = g.report(1.5)
    assert r is not None and r.process == "agent-3" and r.rows is not None
    assert {(k, s, n) for k, s, n, _ in r.rows} == {("not_from_world", X, 6), ("unknown_agent", X, 1)}
    assert g.report(1.6) is None  # unchanged
    g.admit(beacon(99, 40.0, 0.0, t=0.0, radius=2.0), X, KEYS.host_beacons((0, 0), 99), 1.7)
    assert g.report(1.8) is None and g.report(2.6) is not None  # changed, but at most once a second


def test_an_agents_report_is_its_heartbeat_and_says_a_guess_at_once() -> None:
    from reconswarm.net.trust.gate import Gate

    g = Gate(S, "agent-3")
    first = g.report(0.0, counters=(0, -1), every_s=0.5)
    assert first is not None and first.rows is None and (first.rejected, first.guessed_k) == (0, -1)
    assert g.report(0.3, counters=(2, -1), every_s=0.5) is None  # a new count waits for the next beat
    beat = g.report(0.5, counters=(2, -1), every_s=0.5)
    assert beat is not None and (beat.rejected, beat.guessed_k, beat.rows) == (2, -1, None)
    guess = g.report(0.6, counters=(2, 40), every_s=0.5)  # the first guess: at once
    assert guess is not None and guess.guessed_k == 40
    assert g.report(0.7, counters=(2, 40), every_s=0.5) is None
    assert not g.admit(beacon(99, 40.0, 0.0, t=0.0, radius=2.0), X, KEYS.host_beacons((0, 0), 99), 0.8)
    rows = g.report(1.1, counters=(2, 40), every_s=0.5)  # the beat, with the tally that changed
    assert rows is not None and rows.rows is not None and [r[0] for r in rows.rows] == ["unknown_agent"]
    final = g.report(1.2, final=True, counters=(3, 40), every_s=0.5)
    assert final is not None and final.rejected == 3 and final.rows is None  # always, the tally unchanged
    assert Gate(S, "simworld").report(5.0) is None  # the world: only a changed tally, no heartbeat


def test_oversize_obstacle_sets_are_refused_before_decoding() -> None:
    adm = started()
    field = ContourField.from_scenario(S)
    # The largest set the run can send: every obstacle with every contour sample as a vertex.
    full = {oid: tuple((float(x), float(y)) for x, y in field.samples[field.start[m]:field.start[m] + field.count[m]])
            for m, oid in enumerate(field.ids)}
    biggest = wire.obstacles_to_wire(wire.ObstacleSet(10, 2**40, 2**40, full))
    assert adm.check_set_size(len(biggest), A2, KEYS.obstacles((0, 0), 10)) is None
    tri: tuple[tuple[float, float], ...] = ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))
    flood = wire.obstacles_to_wire(wire.ObstacleSet(4, 1, 1, {f"o{i}": tri for i in range(4000)}))
    got = adm.check_set_size(len(flood), X, KEYS.obstacles((0, 0), 4))
    assert kind(got) is K.OVERSIZE and len(flood) > 200_000 > 10 * adm.max_set_bytes  # 255 kB vs 14 kB
