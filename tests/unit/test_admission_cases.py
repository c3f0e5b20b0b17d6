"""Admission's rules (reconswarm/net/trust/admission.py) at their edges, each against what the module's docstring
says: the reachable area (the scenario's extent grown by the largest head offset + 1 m, plus the reach
u_max dt + 1 m), the bound on |u| for each planner kind, one command an agent a tick, the radius and clock
tolerances, who holds an agent's pin, the hull checks and their bounded memory, odometry and reports; and
that every refusal names its sender's session, the key and what was wrong (the tally counts per source,
the log prints the rest)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from reconswarm.net.trust import admission
from reconswarm.net.trust.admission import UNATTRIBUTED, Admission, Intrusion, IntrusionKind, Pins, command_bound_mps
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.plant import unicycle
from reconswarm.scenario.model import AgentSpec, ObstacleSpec, PlannerKind, load
from tests.support import PAPER

PAPER_S = load(PAPER)
KEYS = Keys("edges-0a1b2c")
WORLD, A1, A2, X = "world-zid", "agent1-zid", "agent2-zid", "intruder-zid"
K = IntrusionKind

# A small scenario whose extent is set by different things on each side: starts on the left, the slots
# (p* + Δ_i) on the right and at the top, the box at the bottom. Radii below 1 m.
BOX = ((100.0, -50.0), (120.0, -50.0), (120.0, -40.0), (100.0, -40.0))
S = replace(
    PAPER_S,
    target_m=(500.0, 0.0),
    agents=(AgentSpec(1, (0.0, 0.0), 0.5, (10.0, 0.0), 0.0, 0.5),
            AgentSpec(2, (20.0, 5.0), 0.4, (-10.0, 30.0), 0.0, 0.3)),
    obstacles=(ObstacleSpec("box", BOX),),
)
# The area at t = 0: x in [0, 510], y in [-50, 30] grown by 0.5 m (largest head offset) + 1 m + reach(0) = 1 m.
X_LO, X_HI, Y_LO, Y_HI = 0.0 - 2.5, 510.0 + 2.5, -50.0 - 2.5, 30.0 + 2.5


def beacon(aid: int, px: float, py: float, t: float = 0.0, radius: float | None = None, s=S) -> wire.Beacon:
    r = radius if radius is not None else s.radii[s.agent_index(aid)]
    return wire.Beacon(aid, round(t / s.meta.dt_s), t, px, py, float(r))


def admits_at_start(px: float, py: float) -> bool:
    got = Admission(S).check_beacon(beacon(1, px, py), A1, KEYS.host_beacons((0, 0), 1), now=0.0)
    assert got is None or got.kind is K.POSITION
    return got is None


def refused(i: Intrusion | None, kind: IntrusionKind, source: str, key: str, *words: str) -> bool:
    """The refusal is of this kind, names the sender's session and the key, and its detail says `words`."""
    assert i is not None, "admitted"
    assert (i.kind, i.source, i.key) == (kind, source, key)
    assert isinstance(i.detail, str) and all(w in i.detail for w in words), i.detail
    return True


# ------------------------------------------------------------------------------------------ positions


@pytest.mark.parametrize("side", ["left", "right", "bottom", "top"])
def test_the_reachable_area_at_the_start_is_the_extent_grown_by_head_offset_and_margins(side: str) -> None:
    inside, outside = {
        "left": ((X_LO + 0.05, 0.0), (X_LO - 0.05, 0.0)),
        "right": ((X_HI - 0.05, 0.0), (X_HI + 0.05, 0.0)),
        "bottom": ((0.0, Y_LO + 0.05), (0.0, Y_LO - 0.05)),
        "top": ((0.0, Y_HI - 0.05), (0.0, Y_HI + 0.05)),
    }[side]
    assert admits_at_start(*inside)
    assert not admits_at_start(*outside)


def test_the_area_grows_by_u_max_per_second() -> None:
    adm = Admission(S)
    u = command_bound_mps(S)
    t = 2.0
    ok = adm.check_beacon(beacon(1, X_HI + u * t - 0.05, 0.0, t=t), A1, KEYS.host_beacons((0, 0), 1), now=0.0)
    assert ok is None
    far = Admission(S).check_beacon(beacon(1, X_HI + u * t + 0.05, 0.0, t=t), A1, KEYS.host_beacons((0, 0), 1), now=0.0)
    assert refused(far, K.POSITION, A1, KEYS.host_beacons((0, 0), 1), "outside the reachable area")


def test_a_beacon_may_move_u_max_dt_plus_1_m_from_the_last_one_in_any_direction() -> None:
    adm = Admission(PAPER_S)
    u, dt = command_bound_mps(PAPER_S), 0.05
    step = u * dt + 1.0  # reach_m(dt)
    key = KEYS.host_beacons((0, 0), 2)
    x, y, t = 40.0, 20.0, 10.0
    assert adm.check_beacon(beacon(2, x, y, t=t, s=PAPER_S), A2, key, now=0.0) is None
    for k, ang in enumerate((0.7, 2.0, -1.2, math.pi / 2)):  # just inside the reach, diagonally and along y
        t += dt
        x, y = x + 0.99 * step * math.cos(ang), y + 0.99 * step * math.sin(ang)
        assert adm.check_beacon(beacon(2, x, y, t=t, s=PAPER_S), A2, key, now=0.1 * k) is None, ang
    got = adm.check_beacon(beacon(2, x, y + 1.01 * step, t=t + dt, s=PAPER_S), A2, key, now=1.0)  # along y only
    assert refused(got, K.POSITION, A2, key, "moved", f"in {dt:.6g} s")


# ------------------------------------------------------------------------------------------ commands


def test_command_bound_for_each_planner_kind_speed_limit_and_perturbation() -> None:
    """|u| <= k_att (R_c + max |Δ_i|) + c (N - 1 + M) + perturbation, c = |Ψ| d_max / (d_max - d_safe); the
    virtual leader adds its own velocity (attraction and M obstacle terms) and the containment wall (one
    more c); a world speed limit above that is the bound."""
    p = PAPER_S.planner
    n, m = len(PAPER_S.agents), len(PAPER_S.obstacles)
    att = p.k_att * (p.target_radius_m + max(math.hypot(*a.offset_m) for a in PAPER_S.agents))
    c = abs(p.psi_mps) * p.d_max_m / (p.d_max_m - p.d_safe_m)
    base = att + c * (n - 1 + m)
    assert p.perturbation_mps == 0.0 and PAPER_S.world.max_speed_mps == 0.0
    assert command_bound_mps(PAPER_S) == pytest.approx(base, rel=1e-12)
    shaken = replace(PAPER_S, planner=replace(p, perturbation_mps=0.3))
    assert command_bound_mps(shaken) == pytest.approx(base + 0.3, rel=1e-12)
    leader = PAPER_S.with_planner(PlannerKind.VIRTUAL_LEADER.value)
    assert command_bound_mps(leader) == pytest.approx(base + att + c * m + c, rel=1e-12)
    fast = replace(PAPER_S, world=replace(PAPER_S.world, max_speed_mps=3 * base))
    assert command_bound_mps(fast) == pytest.approx(3 * base, rel=1e-12)
    slow = replace(PAPER_S, world=replace(PAPER_S.world, max_speed_mps=base / 3))
    assert command_bound_mps(slow) == pytest.approx(base, rel=1e-12)


def started(s=PAPER_S) -> Admission:
    adm = Admission(s)
    assert adm.check_clock(wire.Clock(0, 0.0, tuple(a.id for a in s.agents)), WORLD, KEYS.clock) is None
    return adm


def test_the_turn_rate_counts_in_u_through_the_head_offset() -> None:
    """|u| = |M(θ) [v, ω]| = hypot(v, h ω), h the agent's head offset."""
    adm = started()
    h = float(PAPER_S.head_offsets[PAPER_S.agent_index(2)])
    key = KEYS.host(2, "cmd")
    assert adm.check_cmd(wire.Cmd(2, 0, 0.0, 0.99 * adm.u_max / h), A2, key, now=0.0, world_k=0) is None
    got = adm.check_cmd(wire.Cmd(2, 0, 0.0, 1.01 * adm.u_max / h), A2, key, now=0.0, world_k=0)
    assert refused(got, K.COMMAND, A2, key, "above the bound")
    v = 0.6 * adm.u_max
    assert adm.check_cmd(wire.Cmd(2, 1, v, 0.79 * adm.u_max / h), A2, key, now=0.0, world_k=1) is None  # 0.99 u_max
    got = adm.check_cmd(wire.Cmd(2, 1, v, 0.81 * adm.u_max / h), A2, key, now=0.0, world_k=1)  # 1.006 u_max
    assert refused(got, K.COMMAND, A2, key)
    # Float error is forgiven: 1 + 1e-9 relative.
    assert adm.check_cmd(wire.Cmd(2, 2, adm.u_max * (1 + 0.5e-9), 0.0), A2, key, now=0.0, world_k=2) is None
    got = adm.check_cmd(wire.Cmd(2, 2, 2.0, 0.0), A2, key, now=0.0, world_k=1)
    assert refused(got, K.COMMAND, A2, key, "tick 2", "newest tick is 1")


def test_a_ros2_twist_is_bounded_by_where_it_moves_the_head_point_over_the_step() -> None:
    """A robot base holds its cmd_vel over the step: what counts is the head point's speed along that arc (the
    agent sends the twist that moves it by exactly u dt, unicycle.arc_twist), and at most half a turn a step. A
    twist for |u| just under the bound is admitted although hypot(v, h ω) is up to π/2 times |u|."""
    adm = started()
    h, dt = float(PAPER_S.head_offsets[PAPER_S.agent_index(2)]), PAPER_S.meta.dt_s
    key = KEYS.host(2, "cmd")
    v, w = unicycle.arc_twist(-2.0 * h / dt, 1e-3 / h, h, dt)  # straight back by 2 h, a hair aside: a half-turn
    assert math.hypot(v, h * w) > 1.5 * math.hypot(-2.0 * h / dt, 1e-3)
    assert adm.check_cmd(wire.Cmd(2, 0, v, w), A2, key, now=0.0, world_k=0, ticked=False) is None
    for scale, ok in ((0.99, True), (1.01, False)):
        v, w = unicycle.arc_twist(0.0, scale * adm.u_max / h, h, dt)  # |u| = scale u_max, across
        got = adm.check_cmd(wire.Cmd(2, 0, v, w), A2, key, now=0.0, world_k=0, ticked=False)
        assert got is None if ok else refused(got, K.COMMAND, A2, key, "above the bound")
    spin = 2.0 * math.pi / dt  # a whole turn in a step: back where it was, its arc never checked
    got = adm.check_cmd(wire.Cmd(2, 0, 0.0, spin), A2, key, now=0.0, world_k=0, ticked=False)
    assert refused(got, K.COMMAND, A2, key, "half a turn")
    got = adm.check_cmd(wire.Cmd(2, 0, math.inf, 0.0), A2, key, now=0.0, world_k=0, ticked=False)
    assert refused(got, K.COMMAND, A2, key, "above the bound")


def test_a_command_for_an_agent_the_scenario_does_not_have() -> None:
    adm = started()
    key = KEYS.host(99, "cmd")
    for omega in (0.0, 2.0 * adm.u_max):  # an unknown agent has no head offset: ω does not count
        got = adm.check_cmd(wire.Cmd(99, 0, 1.0, omega), X, key, now=0.0, world_k=0)
        assert refused(got, K.UNKNOWN_AGENT, X, key, "agent 99")


def test_one_command_per_agent_and_tick() -> None:
    adm = started()
    key = KEYS.host(2, "cmd")
    assert adm.check_cmd(wire.Cmd(2, 5, 1.0, 0.1), A2, key, now=0.0, world_k=5) is None
    assert adm.check_cmd(wire.Cmd(2, 5, 1.0, 0.1), A2, key, now=0.0, world_k=5) is None  # the same again: fine
    got = adm.check_cmd(wire.Cmd(2, 5, -3.0, 0.7), A2, key, now=0.0, world_k=5)
    assert refused(got, K.CONFLICT, A2, key, "agent 2 tick 5", "(-3, 0.7) after (1, 0.1)")
    assert adm.check_cmd(wire.Cmd(2, 6, -3.0, 0.7), A2, key, now=0.0, world_k=6) is None  # the next tick: free
    # A ROS 2 cmd_vel names no tick: no conflict between two of them.
    ros = started()
    assert ros.check_cmd(wire.Cmd(2, 5, 1.0, 0.1), A2, key, now=0.0, world_k=5, ticked=False) is None
    assert ros.check_cmd(wire.Cmd(2, 5, -3.0, 0.7), A2, key, now=0.0, world_k=5, ticked=False) is None


def test_conflicts_on_recent_ticks_are_still_seen_after_old_ticks_are_forgotten() -> None:
    adm = started()
    n = len(PAPER_S.agents)
    ids = [a.id for a in PAPER_S.agents]
    sessions = {a: f"agent{a}-zid" for a in ids}
    for k in range(200):  # 200 ticks of every agent's command: far more than 64 per agent are remembered
        for a in ids:
            key = KEYS.host(a, "cmd")
            assert adm.check_cmd(wire.Cmd(a, k, 1.0, 0.0), sessions[a], key, now=0.001 * k, world_k=k) is None
        assert len(adm.cmds) <= 64 * n + n
    for back in (0, 10, 31):  # a different command for a recent tick of agent 2: a conflict
        got = adm.check_cmd(wire.Cmd(2, 199 - back, 2.0, 0.0), sessions[2], KEYS.host(2, "cmd"), now=0.2, world_k=199)
        assert got is not None and got.kind is K.CONFLICT, back


# ------------------------------------------------------------------------------------------ tolerances


def test_the_radius_tolerance_is_relative_above_1_m_and_absolute_below() -> None:
    key = KEYS.host_beacons((0, 0), 2)
    big = replace(S, agents=(S.agents[0], replace(S.agents[1], radius_m=50.0)))
    assert Admission(big).check_beacon(beacon(2, 20.0, 5.0, radius=50.0 * (1 + 0.8e-9), s=big), A2, key, 0.0) is None
    got = Admission(big).check_beacon(beacon(2, 20.0, 5.0, radius=50.0 * (1 + 1.2e-9), s=big), A2, key, 0.0)
    assert refused(got, K.RADIUS, A2, key, "the scenario's is 50.0 m")
    # Agent 2's radius is 0.4 m: 1e-9 m either way.
    assert Admission(S).check_beacon(beacon(2, 20.0, 5.0, radius=0.4 + 0.8e-9), A2, key, 0.0) is None
    got = Admission(S).check_beacon(beacon(2, 20.0, 5.0, radius=0.4 + 1.5e-9), A2, key, 0.0)
    assert refused(got, K.RADIUS, A2, key)


def test_the_clock_tolerance_on_t_equals_k_dt() -> None:
    dt = PAPER_S.meta.dt_s
    ids = tuple(a.id for a in PAPER_S.agents)
    k = 20_000
    t = k * dt  # 1000 s: relative 1e-9
    long = replace(PAPER_S, meta=replace(PAPER_S.meta, duration_s=2000.0))
    assert started(long).check_clock(wire.Clock(k, t * (1 + 0.5e-9), ids), WORLD, KEYS.clock) is None
    got = started(long).check_clock(wire.Clock(k, t * (1 + 2e-9), ids), WORLD, KEYS.clock)
    assert refused(got, K.CLOCK, WORLD, KEYS.clock, f"at tick {k}")
    # Below 1 s: 1e-9 s absolute.
    assert started().check_clock(wire.Clock(10, 10 * dt + 0.5e-9, ids), WORLD, KEYS.clock) is None
    got = started().check_clock(wire.Clock(10, 10 * dt + 1.5e-9, ids), WORLD, KEYS.clock)
    assert refused(got, K.CLOCK, WORLD, KEYS.clock, "at tick 10")
    adm = started()
    got = adm.check_clock(wire.Clock(1, dt, ids, mode=wire.ClockMode.REALTIME, speed=4.0), WORLD, KEYS.clock)
    assert refused(got, K.CLOCK, WORLD, KEYS.clock, "mode realtime x4", "the run's is lockstep x0")


def test_a_clock_after_the_missions_last_tick_is_refused() -> None:
    """The world ends the mission at its duration (tick duration / dt): a later tick is forged, an end above all
    (one claiming a far tick was not refuted by the world's clocks, which never reach it)."""
    dt, ids = PAPER_S.meta.dt_s, tuple(a.id for a in PAPER_S.agents)
    last = round(PAPER_S.meta.duration_s / dt)
    assert started().check_clock(wire.Clock(last, last * dt, ids, end=True, reason="duration"), WORLD,
                                 KEYS.clock) is None
    got = started().check_clock(wire.Clock(last + 1, (last + 1) * dt, ids, end=True, reason="duration"), WORLD,
                                KEYS.clock)
    assert refused(got, K.CLOCK, WORLD, KEYS.clock, f"tick {last + 1} after the mission's last ({last})")


# ------------------------------------------------------------------------------------------ who speaks


def test_each_agent_has_its_own_pin() -> None:
    adm = started()
    key1, key2 = KEYS.host(1, "cmd"), KEYS.host(2, "cmd")
    for k in range(5):  # two agents commanding every tick, each from its own session
        now = 0.05 * k
        assert adm.check_cmd(wire.Cmd(1, 0, 1.0, 0.0), A1, key1, now=now, world_k=0) is None
        assert adm.check_cmd(wire.Cmd(2, 0, 1.0, 0.0), A2, key2, now=now, world_k=0) is None
    got = adm.check_cmd(wire.Cmd(2, 0, 1.0, 0.0), A1, key2, now=0.3, world_k=0)  # agent 1's session for agent 2
    assert refused(got, K.IMPERSONATION, A1, key2, "agent 2 speaks from session agent2-zid")


def test_an_unattributed_message_never_pins_an_agent() -> None:
    pins = Pins()
    assert not pins.agent(3, UNATTRIBUTED, 0.0)
    assert 3 not in pins.agents
    assert pins.agent(3, "agent3-zid", 0.1)  # the agent's own session pins it next
    adm = started()
    got = adm.check_cmd(wire.Cmd(3, 0, 1.0, 0.0), UNATTRIBUTED, KEYS.host(3, "cmd"), now=0.0, world_k=0)
    assert refused(got, K.IMPERSONATION, UNATTRIBUTED, KEYS.host(3, "cmd"), "agent 3 speaks from session nobody")


def test_refusals_name_the_sender_the_key_and_the_reason() -> None:
    adm = started()
    bkey = KEYS.host_beacons((0, 0), 2)
    phantom = beacon(99, 40.0, 0.0, radius=2.0, s=PAPER_S)
    assert refused(adm.check_beacon(phantom, X, bkey, 0.0), K.UNKNOWN_AGENT, X, bkey, "agent 99 is not in the scenario")
    assert refused(adm.check_beacon(beacon(2, 40.0, 0.0, radius=9.0, s=PAPER_S), X, bkey, 0.0), K.RADIUS, X, bkey,
                   "radius 9 m")
    assert refused(adm.check_beacon(beacon(2, 1e7, 0.0, s=PAPER_S), X, bkey, 0.0), K.POSITION, X, bkey, "(1e+07, 0)")
    assert adm.check_beacon(beacon(2, 40.0, 0.0, t=10.0, s=PAPER_S), A2, bkey, 0.0) is None
    assert refused(adm.check_beacon(beacon(2, 40.0, 0.0, t=10.0, s=PAPER_S), X, bkey, 0.1), K.IMPERSONATION, X, bkey,
                   "agent 2 speaks from session agent2-zid")
    skey = KEYS.host(2, "state")
    assert refused(adm.check_world_source(X, skey), K.NOT_FROM_WORLD, X, skey,
                   "the world speaks from session world-zid")
    fresh = Admission(PAPER_S)
    got = fresh.check_world_source(UNATTRIBUTED, skey)
    assert refused(got, K.NOT_FROM_WORLD, UNATTRIBUTED, skey)
    assert got is not None and got.detail == "the world speaks from session (none yet)"
    tick = wire.Clock(3, 3 * PAPER_S.meta.dt_s, ())
    assert refused(adm.check_clock(tick, X, KEYS.clock), K.NOT_FROM_WORLD, X, KEYS.clock, "world-zid")
    end = wire.Clock(3, 3 * PAPER_S.meta.dt_s, (), end=True, reason="converged")
    assert refused(adm.check_clock(end, X, KEYS.clock), K.NOT_FROM_WORLD, X, KEYS.clock, "world-zid",
                   "claims the end: 'converged'")
    okey = KEYS.obstacles((0, 0), 2)
    assert refused(adm.check_obstacles(wire.ObstacleSet(99, 1, 1, {}), X, okey), K.UNKNOWN_AGENT, X, okey, "agent 99")
    assert refused(adm.check_set_size(adm.max_set_bytes + 1, X, okey), K.OVERSIZE, X, okey,
                   f"{adm.max_set_bytes + 1} bytes", f"largest is {adm.max_set_bytes}")
    assert refused(adm.check_report(None, X, KEYS.report("simworld"), 0.0), K.IMPERSONATION, X,
                   KEYS.report("simworld"), "simworld speaks from session world-zid")


# ------------------------------------------------------------------------------------------ obstacle sets


def test_obstacle_set_size_up_to_the_runs_largest_is_admitted() -> None:
    adm = started()
    okey = KEYS.obstacles((0, 0), 2)
    assert adm.check_set_size(adm.max_set_bytes, A2, okey) is None
    assert adm.check_set_size(adm.max_set_bytes + 1, A2, okey) is not None


def test_one_unknown_obstacle_id_is_refused_and_named_cut_to_40_characters() -> None:
    adm = started()
    okey = KEYS.obstacles((0, 0), 2)
    got = adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {"nowhere": ((0.0, 0.0),)}), X, okey)
    assert refused(got, K.UNKNOWN_OBSTACLE, X, okey, "1 obstacle id(s)", "'nowhere'")
    long_id = "x" * 39 + "yz" + "w" * 60
    got = adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {long_id: ((0.0, 0.0),)}), X, okey)
    assert refused(got, K.UNKNOWN_OBSTACLE, X, okey, repr(long_id[:40]))
    assert got is not None and "xy" not in got.detail.replace(repr(long_id[:40]), "")  # no 41st character


def test_hull_vertex_count_up_to_the_sensed_samples_and_an_empty_hull() -> None:
    adm = Admission(S)
    okey = KEYS.obstacles((0, 0), 2)
    cap = adm.max_vertices["box"]
    (x0, y0), (x1, y1) = BOX[0], BOX[1]  # points along the bottom edge: on the boundary
    on_edge = tuple((x0 + (x1 - x0) * i / cap, y0) for i in range(cap))
    assert adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {"box": on_edge}), A2, okey) is None
    more = (*on_edge, (x1, y1))
    got = adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {"box": more}), X, okey)
    assert refused(got, K.HULL, X, okey, "'box'", f"{cap + 1} vertices, at most {cap}")
    assert adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {"box": ()}), A2, okey) is None  # claims nothing
    off = ((110.0, -45.0), (x0, y0))  # the box's centre: 5 m inside
    assert refused(adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {"box": off}), X, okey), K.HULL, X, okey,
                   "a vertex 5 m off the obstacle's boundary")


def test_the_memory_of_checked_hulls_holds_exactly_its_vertex_budget() -> None:
    adm = Admission(S, hull_vertices_kept=6)
    okey = KEYS.obstacles((0, 0), 2)

    def tri(k: int) -> tuple[tuple[float, float], ...]:  # three distinct points on the bottom edge
        return tuple((100.0 + k + d, -50.0) for d in (0.1, 0.2, 0.3))

    for k in range(4):
        assert adm.check_obstacles(wire.ObstacleSet(2, 1, 1, {"box": tri(k)}), A2, okey) is None
    # 3 + 3 vertices fill the budget of 6; the third hull starts afresh, the fourth fits beside it.
    assert adm.hulls_ok == {("box", tri(2)), ("box", tri(3))}


def test_a_processs_gates_share_their_hull_checks_each_refusal_counted_by_its_own_gate(monkeypatch) -> None:
    """An agent host's agents ask one HullChecks: a good hull that every co-hosted agent receives is measured once;
    a bad one is refused by each agent's gate and counted in that gate's tally alone."""
    measured: list[int] = []
    real = admission.signed_distance

    def counting(*args, **kwargs):
        measured.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(admission, "signed_distance", counting)
    hulls = admission.HullChecks(S)
    gates = [Gate(S, f"agent-{a}", hulls=hulls) for a in (1, 2)]
    okey = KEYS.obstacles((0, 0), 2)
    good = wire.ObstacleSet(2, 1, 1, {"box": ((101.0, -50.0), (105.0, -50.0), (120.0, -45.0))})
    assert [g.admit(good, A2, okey, 0.0) for g in gates] == [True, True]
    assert len(measured) == 1 and gates[0].adm.hulls_ok == gates[1].adm.hulls_ok == {("box", good.obstacles["box"])}
    bad = wire.ObstacleSet(2, 2, 1, {"box": ((110.0, -45.0), (100.0, -50.0))})  # the box's centre: 5 m inside
    assert gates[0].admit(bad, X, okey, 0.0) is False
    assert (gates[0].count, gates[1].count) == (1, 0)
    assert gates[1].admit(bad, X, okey, 0.0) is False
    assert (gates[0].count, gates[1].count) == (1, 1) and len(measured) == 3  # (a refused hull is never kept)
    lone = [Gate(S, f"agent-{a}") for a in (1, 2)]  # (gates of their own: each measures)
    assert [g.admit(good, A2, okey, 0.0) for g in lone] == [True, True] and len(measured) == 5


# ------------------------------------------------------------------------------------------ odometry, reports


def test_odometry_from_the_world_within_reach_of_the_last_pose() -> None:
    adm = started()
    u, dt = adm.u_max, PAPER_S.meta.dt_s
    x0, y0 = (float(v) for v in PAPER_S.starts[PAPER_S.agent_index(2)])

    def odom(k: int, x: float, y: float) -> wire.State:
        return wire.State(2, k, k * dt, x, y, 0.0, x, y)

    key = KEYS.host(2, "state")
    assert adm.check_odometry(odom(0, x0, y0), WORLD, key) is None
    step = 0.99 * (u * dt + 1.0)
    assert adm.check_odometry(odom(1, x0 + 0.6 * step, y0 + 0.8 * step), WORLD, key) is None
    got = adm.check_odometry(odom(2, x0 + 0.6 * step, y0 + 0.8 * step + 1.02 * (u * dt + 1.0)), WORLD, key)
    assert refused(got, K.POSITION, WORLD, key, "odometry moved", f"in {dt:.6g} s")
    got = adm.check_odometry(odom(2, x0 + 0.6 * step + 1.02 * (u * dt + 1.0), y0 + 0.8 * step), WORLD, key)
    assert refused(got, K.POSITION, WORLD, key, "odometry moved")  # along x only
    assert refused(adm.check_odometry(odom(2, x0, y0), X, key), K.NOT_FROM_WORLD, X, key)
    assert refused(adm.check_odometry(odom(2, 1e8, y0), WORLD, key), K.POSITION, WORLD, key, "outside the reachable")
    assert adm.last_odom[2] == (dt, x0 + 0.6 * step, y0 + 0.8 * step, -1)  # refused poses are not remembered


def test_reports_come_from_the_agent_or_the_world_they_name() -> None:
    adm = started()
    assert adm.check_report(None, WORLD, KEYS.report("simworld"), 0.0) is None
    assert adm.check_report(2, A2, KEYS.report("agent-2"), 0.0) is None  # pins agent 2
    got = adm.check_report(2, X, KEYS.report("agent-2"), 0.1)
    assert refused(got, K.IMPERSONATION, X, KEYS.report("agent-2"), "agent 2 speaks from session agent2-zid")
    got = adm.check_report(99, X, KEYS.report("agent-99"), 0.1)
    assert refused(got, K.UNKNOWN_AGENT, X, KEYS.report("agent-99"))
    got = Admission(PAPER_S).check_report(None, X, KEYS.report("simworld"), 0.0)
    assert refused(got, K.IMPERSONATION, X, KEYS.report("simworld"))
    assert got is not None and got.detail == "simworld speaks from session (none yet)"
