"""The world's plant (simworld/robots.py) in the cases its mutation run (bench/mutation.py) found untested: what a
tick's truth and states say, a held robot in a scan with no contour in range, the world's speed and turn
limits, and a robot commanded at every tick moving at every tick. Pure: no zenoh."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from reconswarm.net.wire.cells import CellGrid
from reconswarm.plant import unicycle
from simworld.robots import Robots
from tests.unit.test_world_node import IDS, S

DT = S.meta.dt_s


def test_a_ticks_truth_and_states_say_its_tick_time_and_every_robots_pose() -> None:
    plant = Robots(S, 0.2)
    plant.theta = plant.theta + np.linspace(0.1, 1.0, len(IDS))  # distinct headings
    plant.p = plant.p + np.column_stack([np.arange(len(IDS)), 2.0 * np.arange(len(IDS))])
    plant.p[0] = np.asarray(S.obstacles[0].vertices_m[0]) - 1.0  # next to an obstacle: it has a scan
    truth, states = plant.observe(3, set(IDS))
    c = unicycle.body_centre(plant.p, plant.theta, S.head_offsets)  # s = p - l [cos θ, sin θ]
    assert (truth.k, truth.t, truth.ids) == (3, pytest.approx(3 * DT), tuple(IDS))
    assert truth.x == tuple(c[:, 0]) and truth.y == tuple(c[:, 1]) and truth.theta == tuple(plant.theta)
    assert truth.px == tuple(plant.p[:, 0]) and truth.py == tuple(plant.p[:, 1])
    for i, m in enumerate(states):
        assert (m.id, m.k, m.t) == (IDS[i], 3, pytest.approx(3 * DT))
    scan = states[0].scan
    assert scan is not None and scan.points and (scan.id, scan.k, scan.t) == (IDS[0], 3, pytest.approx(3 * DT))


def test_a_held_robot_near_a_live_one_is_in_its_scan_even_with_no_contour_in_range() -> None:
    plant = Robots(S, 0.2)
    far = np.array([-5000.0, 3000.0])  # nowhere near an obstacle
    plant.p[0] = far
    plant.p[1] = far + np.array([3.0, 4.0])  # 5 m away; its agent is gone
    _, states = plant.observe(0, set(IDS) - {IDS[1]})
    scan = states[0].scan
    assert scan is not None and scan.points == () and scan.bodies == ((IDS[1], far[0] + 3.0, far[1] + 4.0),)
    assert states[1].scan is None  # (a robot whose agent is gone hears nothing)


def test_the_worlds_speed_and_turn_limits_bind_the_plant() -> None:
    limited = replace(S, world=replace(S.world, max_speed_mps=1.0, max_turn_rate_radps=0.5))
    plant = Robots(limited, 0.2)
    p0, th0 = plant.p.copy(), plant.theta.copy()
    for a in IDS:
        plant.command(a, 0, 5.0, 3.0)  # asks for 5 m/s and 3 rad/s
    plant.apply(0)
    # v ≤ 1 m/s and ω ≤ 0.5 rad/s: the head point moves at most |u| dt = sqrt(v² + l² ω²) dt (eq. 3), the heading
    # turns at most 0.5 dt
    step = np.hypot(*(plant.p - p0).T)
    assert np.all(step <= np.hypot(1.0, S.head_offsets * 0.5) * DT + 1e-9) and np.all(step > 0)
    turn = np.abs(np.angle(np.exp(1j * (plant.theta - th0))))
    assert np.all(turn <= 0.5 * DT + 1e-9) and np.all(turn > 0)


def test_a_robot_commanded_at_every_tick_moves_at_every_tick() -> None:
    plant = Robots(S, 0.2)  # holds a command 4 ticks
    for k in range(12):
        before = plant.p.copy()
        for a in IDS:
            plant.command(a, k, 1.0, 0.0)
        assert plant.apply(k) == set(range(len(IDS)))
        assert np.hypot(*(plant.p - before).T) == pytest.approx(1.0 * DT)  # straight at 1 m/s


def apart(plant: Robots | None = None) -> Robots:
    """Every robot far from every obstacle and from each other (commands of (0, 0): they stand still), in a new
    plant holding commands 0.2 s or the one given."""
    plant = Robots(S, 0.2) if plant is None else plant
    for i in range(len(IDS)):
        plant.p[i] = np.array([-5000.0, 3000.0 + 1000.0 * i])
    return plant


def moved(plant: Robots, k: int) -> np.ndarray:
    """How far each head point moves over the step k -> k+1."""
    before = plant.p.copy()
    plant.apply(k)
    return np.hypot(*(plant.p - before).T)


def test_a_scan_with_as_many_contour_points_as_held_robots_is_sent() -> None:
    """Robot 0 sees one contour point (an obstacle's vertex, just within R_v) and one held robot: its scan has
    both."""
    plant = apart()
    vertex = np.asarray(S.obstacles[0].vertices_m[0])  # (345, 0), the diamond's right-hand vertex
    plant.p[0] = vertex + np.array([S.planner.sensing_range_m - 0.25, 0.0])
    plant.p[1] = plant.p[0] + np.array([0.0, 5.0])  # its agent is gone
    scan = plant.observe(0, set(IDS) - {IDS[1]})[1][0].scan
    assert scan is not None and len(scan.points) == 1 and scan.points[0][:2] == tuple(vertex)
    assert scan.bodies == ((IDS[1], *plant.p[1].tolist()),)


def test_a_held_robot_is_reported_within_reach_plus_two_steps_and_not_beyond() -> None:
    """docs/wire.md: the scan reports every held robot within reach + 2 V dt of an agent (the cell grid's reach
    and V dt)."""
    grid = CellGrid.for_scenario(S)
    edge = grid.reach_m + 2.0 * grid.step_m
    for d, seen in ((edge - 0.01, True), (edge + 0.01, False)):
        plant = apart()
        plant.p[1] = plant.p[0] + np.array([0.0, d])
        scan = plant.observe(0, set(IDS) - {IDS[1]})[1][0].scan
        assert (scan is not None and [b[0] for b in scan.bodies] == [IDS[1]]) is seen, d


def test_a_missing_command_is_held_one_tick_when_hold_sim_s_is_one_tick_then_the_robot_stops() -> None:
    plant = Robots(S, DT)
    for a in IDS:
        plant.command(a, 0, 1.0, 0.0)
    assert moved(plant, 0) == pytest.approx(1.0 * DT)  # its own tick
    assert moved(plant, 1) == pytest.approx(1.0 * DT)  # tick 1's command missing: tick 0's held for one tick
    assert np.all(moved(plant, 2) == 0.0)  # then it stops


def test_a_late_command_counts_while_held_and_one_older_than_the_hold_or_than_the_last_is_ignored() -> None:
    """hold_sim_s = 0.2 s is 4 ticks: robot 0's command for tick 0 arriving at tick 4 is still held over the step
    4 -> 5 (1 m/s), not over 5 -> 6; robot 1's for tick 2 arriving at tick 10 and robot 0's for tick 5 arriving
    after its command for tick 6 are ignored."""
    plant = apart()
    for k in range(4):
        assert np.all(moved(plant, k) == 0.0)  # nobody commands
    plant.command(IDS[0], 0, 1.0, 0.0)  # late, for tick 0
    assert moved(plant, 4).tolist() == pytest.approx([1.0 * DT] + [0.0] * (len(IDS) - 1))
    assert np.all(moved(plant, 5) == 0.0)
    for k in range(6, 10):
        plant.command(IDS[0], k, 0.0, 0.0)
        plant.apply(k)
    plant.command(IDS[1], 2, 1.0, 0.0)  # 8 ticks late: older than the hold
    plant.command(IDS[0], 5, 1.0, 0.0)  # older than robot 0's last command (tick 9)
    assert np.all(moved(plant, 10) == 0.0)


def test_held_bodies_without_a_tick_is_the_start_only_robots_whose_agents_are_gone() -> None:
    """Nobody has commanded yet: at the start (no tick given, tick 0) nobody stands still for want of commands."""
    plant = apart()
    plant.p[1] = plant.p[0] + np.array([0.0, 5.0])
    assert plant.held_bodies(set(IDS)) == [()] * len(IDS)
    assert plant.held_bodies(set(IDS) - {IDS[1]})[0] == ((IDS[1], *plant.p[1].tolist()),)


def test_a_robot_never_commanded_is_held_from_tick_1_even_with_a_hold_of_many_ticks() -> None:
    """hold_sim_s = 5 s (100 ticks): a robot whose agent never commanded is held from tick 1 all the same (its
    commands never came; docs/wire.md), not only 100 ticks after some earlier time."""
    plant = Robots(S, 5.0)
    for i in range(len(IDS)):
        plant.p[i] = np.array([-5000.0, 3000.0 + 1000.0 * i])
    plant.p[1] = plant.p[0] + np.array([0.0, 5.0])
    for a in IDS[:1] + IDS[2:]:  # everyone but agent 1 (alive by its token) commands tick 0
        plant.command(a, 0, 0.0, 0.0)
    plant.apply(0)
    scan = plant.observe(1, set(IDS))[1][0].scan
    assert scan is not None and scan.bodies == ((IDS[1], *plant.p[1].tolist()),)
