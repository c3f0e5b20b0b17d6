"""The world's plant (simworld/plant.py) in the cases its mutation run (bench/mutation.py) found untested: what a
tick's truth and states say, a held robot in a scan with no contour in range, the world's speed and turn
limits, and a robot commanded at every tick moving at every tick. Pure: no zenoh."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from reconswarm.plant import unicycle
from simworld.plant import Plant
from tests.unit.test_world_node import IDS, S

DT = S.meta.dt_s


def test_a_ticks_truth_and_states_say_its_tick_time_and_every_robots_pose() -> None:
    plant = Plant(S, 0.2)
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
    plant = Plant(S, 0.2)
    far = np.array([-5000.0, 3000.0])  # nowhere near an obstacle
    plant.p[0] = far
    plant.p[1] = far + np.array([3.0, 4.0])  # 5 m away; its agent is gone
    _, states = plant.observe(0, set(IDS) - {IDS[1]})
    scan = states[0].scan
    assert scan is not None and scan.points == () and scan.bodies == ((IDS[1], far[0] + 3.0, far[1] + 4.0),)
    assert states[1].scan is None  # (a robot whose agent is gone hears nothing)


def test_the_worlds_speed_and_turn_limits_bind_the_plant() -> None:
    limited = replace(S, world=replace(S.world, max_speed_mps=1.0, max_turn_rate_radps=0.5))
    plant = Plant(limited, 0.2)
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
    plant = Plant(S, 0.2)  # holds a command 4 ticks
    for k in range(12):
        before = plant.p.copy()
        for a in IDS:
            plant.command(a, k, 1.0, 0.0)
        assert plant.apply(k) == set(range(len(IDS)))
        assert np.hypot(*(plant.p - before).T) == pytest.approx(1.0 * DT)  # straight at 1 m/s
