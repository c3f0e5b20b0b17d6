"""Which held robots a scan reports (simworld/robots.py, `bodies`): a robot is in the scans of the live agents near
it when its agent is gone, and also, from tick 1 on, when it stands still because its agent's commands stopped
`hold_sim_s` ago or never came (an agent alive by its token that never spoke is heard by nobody, so its robot
would otherwise be in nobody's plan). A swarm that commands every tick sees no bodies. Pure: no zenoh."""

from __future__ import annotations

import numpy as np

from simworld.robots import Robots
from tests.unit.test_world_node import IDS, S

HOLD_S = 0.2
HOLD_TICKS = round(HOLD_S / S.meta.dt_s)


def near_pair() -> Robots:
    """Robots 0 and 1 side by side, 5 m apart, far from every obstacle and every other robot."""
    plant = Robots(S, HOLD_S)
    far = np.array([-5000.0, 3000.0])
    plant.p[0], plant.p[1] = far, far + np.array([3.0, 4.0])
    for i in range(2, len(IDS)):
        plant.p[i] = far + np.array([0.0, 2000.0 + 100.0 * i])
    return plant


def command(plant: Robots, k: int, agents: list[int]) -> None:
    for a in agents:
        plant.command(a, k, 0.0, 0.0)  # (standing still: positions stay as set)
    plant.apply(k)


def bodies(plant: Robots, k: int, i: int) -> tuple[tuple[int, float, float], ...]:
    scan = plant.observe(k, set(IDS))[1][i].scan
    return () if scan is None else scan.bodies


def test_a_robot_whose_live_agent_never_commanded_is_reported_from_tick_1() -> None:
    plant = near_pair()
    assert bodies(plant, 0, 0) == ()  # tick 0: nobody has commanded yet; nobody is held
    command(plant, 0, IDS[:1] + IDS[2:])  # everyone but agent 1 (alive by its token) commands tick 0
    p1 = plant.p[1]
    assert bodies(plant, 1, 0) == ((IDS[1], float(p1[0]), float(p1[1])),)
    assert bodies(plant, 1, 1) == ()  # (its own scan does not list itself)


def test_a_robot_is_reported_once_its_agents_last_command_is_no_longer_held() -> None:
    plant = near_pair()
    command(plant, 0, IDS)
    for k in range(1, HOLD_TICKS + 1):  # agent 1 falls silent after tick 0: its robot holds that command
        assert bodies(plant, k, 0) == ()
        command(plant, k, IDS[:1] + IDS[2:])
    k = HOLD_TICKS + 1  # tick 0's command held for HOLD_TICKS ticks: the robot is stopped now
    assert [b[0] for b in bodies(plant, k, 0)] == [IDS[1]]
    command(plant, k, IDS)  # it commands again: no longer held
    assert bodies(plant, k + 1, 0) == ()


def test_a_swarm_commanding_every_tick_sees_no_bodies() -> None:
    plant = near_pair()
    for k in range(3 * HOLD_TICKS):
        assert all(bodies(plant, k, i) == () for i in range(len(IDS)))
        command(plant, k, IDS)
