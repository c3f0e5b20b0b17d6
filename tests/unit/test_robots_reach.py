"""How far the world drives a robot on a command of an earlier tick (simworld/robots.py, `hold_reach_m`): held, or
taken late, only while the robot stands within d_safe / 2 of where its agent planned it; a command of its own tick
always. Pure: no zenoh."""

from __future__ import annotations

import numpy as np
import pytest

from simworld.robots import Robots
from simworld.ros2_io import Ros2Robots
from tests.unit.test_robots_cases import apart as spread
from tests.unit.test_robots_cases import moved
from tests.unit.test_world_node import IDS, S

DT = S.meta.dt_s


def apart(plant: Robots) -> Robots:
    """test_robots_cases.apart, every robot heading along +x."""
    spread(plant).theta[:] = 0.0
    return plant


def test_the_reach_is_half_of_d_safe() -> None:
    assert S.planner.d_safe_m == 2.0 and Robots(S, 0.2).hold_reach_m == 1.0


@pytest.mark.parametrize("plant_kind", [Robots, Ros2Robots])
def test_a_missing_command_is_held_only_while_the_robot_stands_within_reach_of_where_it_was_planned(
        plant_kind: type[Robots]) -> None:
    """7 m/s is 0.35 m a step: held from 0.35 and 0.7 m away, not from 1.05 m, though `hold_sim_s` (4 ticks)
    would still hold it. The same for a robot base holding its (v, ω) (ROS 2 mode)."""
    plant = apart(plant_kind(S, 0.2))
    plant.command(IDS[0], 0, 7.0, 0.0)
    steps = [moved(plant, k)[0] for k in range(6)]
    assert steps == pytest.approx([7.0 * DT] * 3 + [0.0] * 3)
    assert plant.expired(3).tolist()[0] is False and plant.stopped(3).tolist()[0] is True


def test_a_fast_command_moves_its_own_tick_and_is_not_held_beyond_it() -> None:
    """78 m/s (the paper's repulsion near a neighbour) is 3.9 m a step: farther than the reach at once."""
    plant = apart(Robots(S, 0.2))
    plant.command(IDS[0], 0, 78.0, 0.0)
    assert [moved(plant, k)[0] for k in range(3)] == pytest.approx([78.0 * DT, 0.0, 0.0])


def test_a_robot_commanded_at_every_tick_moves_at_every_tick_however_fast() -> None:
    """Lockstep's case: every command is its own tick's, planned where the robot stands (the engine's steps)."""
    plant = apart(Robots(S, 0.2))
    for k in range(5):
        for a in IDS:
            plant.command(a, k, 78.0, 0.0)
        assert moved(plant, k) == pytest.approx(np.full(len(IDS), 78.0 * DT))


def test_late_commands_planned_where_the_robot_stood_drive_it_only_within_reach() -> None:
    """The contact seen at --speed 10 under a flood: an agent far behind sends, one after the other, the commands
    of ticks when its robot stood still, each planned from that same point. The first is the step it planned (late);
    the next ones would drive the robot on from farther and farther away: fast ones are refused at once, slow ones
    once the robot stands more than the reach from that point."""
    plant = apart(Robots(S, 0.2))
    for k in range(5):
        assert np.all(moved(plant, k) == 0.0)  # nobody commands: everyone stands (ticks 0-4)
    steps = []
    for k in range(5, 10):  # the commands of ticks 1-5, when the robots stood where they stand
        plant.command(IDS[0], k - 4, 78.0, 0.0)
        plant.command(IDS[1], k - 4, 6.0, 0.0)
        steps.append(moved(plant, k)[:2].tolist())
    np.testing.assert_allclose(steps, [[3.9, 0.3], [0.0, 0.3], [0.0, 0.3], [0.0, 0.3], [0.0, 0.0]], atol=1e-9)


def test_a_robot_no_command_moved_is_reported_held_in_its_neighbours_scans_at_the_next_tick() -> None:
    """Robot 1's fast command is not held beyond its tick: at the next tick it stands still for want of a command
    (its hold has not expired) and robot 0, 5 m away, hears of it in its scan; robot 2, held moving, is not."""
    plant = apart(Robots(S, 0.2))
    plant.p[1] = plant.p[0] + np.array([0.0, 5.0])
    plant.p[2] = plant.p[0] + np.array([0.0, -5.0])
    for a in IDS:
        plant.command(a, 0, 0.0, 0.0)
    plant.command(IDS[1], 0, 78.0, 0.0)
    plant.command(IDS[2], 0, 6.0, 0.0)
    plant.apply(0)
    plant.apply(1)  # nobody commands tick 1: robot 1 stops; robot 2 and the standing ones are held
    assert plant.halted.tolist()[:3] == [False, True, False]
    scan = plant.observe(2, set(IDS))[1][0].scan
    assert scan is not None and [b[0] for b in scan.bodies] == [IDS[1]]
