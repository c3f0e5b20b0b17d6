"""Issue 20's admission rules, pure: ROS 2 input goes through the rules of the project's own messages
(odometry only from the plant's session and a pose the robot can have reached; cmd_vel bounded and only from
the agent's session; no number from the wire crashes anything), one command per agent and tick, a token
without data does not hold a lockstep tick up, and one forged message heard by many counts once."""

from __future__ import annotations

import math

import pytest

from reconswarm.net.ros2 import ros2
from reconswarm.net.timing import Timing
from reconswarm.net.trust.admission import Admission, IntrusionKind
from reconswarm.net.trust.gate import Gate
from reconswarm.net.trust.membership import Membership, Policy
from reconswarm.net.wire import wire
from reconswarm.net.wire.cells import CellGrid
from reconswarm.net.wire.keys import Keys
from reconswarm.record.summary import distinct_intrusions
from reconswarm.scenario.model import load
from tests.support import PAPER

S = load(PAPER)
DT = S.meta.dt_s
WORLD, A3, X = "world-zid", "agent3-zid", "outsider-zid"
ODOM3, CMD3 = ros2.odom_key(0, 3), ros2.cmd_vel_key(0, 3)
K = IntrusionKind


def odom_state(k: int, x: float, y: float) -> wire.State:
    """An odometry of robot 3 as its agent decodes it (agent/ros2_io.py)."""
    return wire.State(3, k, k * DT, x, y, 0.0, x + 0.5, y)


def pinned() -> Admission:
    adm = Admission(S)
    assert adm.check_clock(wire.Clock(0, 0.0, (1, 2, 3)), WORLD, "clock") is None  # pins the world
    return adm


def test_odometry_only_from_the_plant_and_only_where_the_robot_can_be() -> None:
    adm = pinned()
    x0, y0 = (float(v) for v in S.starts[S.agent_index(3)])
    assert adm.check_odometry(odom_state(10, x0, y0), WORLD, ODOM3) is None
    # robot 3's odometry replayed from another session, shifted by 40 m: not the plant's
    got = adm.check_odometry(odom_state(10, x0 + 40.0, y0), X, ODOM3)
    assert got is not None and (got.kind, got.source) == (K.NOT_FROM_WORLD, X)
    # the same stamped with the plant's id: 40 m in no time cannot be
    got = adm.check_odometry(odom_state(10, x0 + 40.0, y0), WORLD, ODOM3)
    assert got is not None and got.kind is K.POSITION
    # far outside anything the robot can reach by then
    assert adm.check_odometry(odom_state(11, 1.3e308, -1.3e308), WORLD, ODOM3).kind is K.POSITION  # type: ignore[union-attr]
    # the real next odometry still passes (the refused ones were not remembered)
    assert adm.check_odometry(odom_state(11, x0 + 0.05, y0), WORLD, ODOM3) is None


def test_cmd_vel_is_bounded_and_only_from_the_agents_session() -> None:
    gate = Gate(S, "simworld")
    gate.world_k = 5
    ok = wire.Cmd(3, 5, 0.8, 0.1)
    assert gate.admit_twist(ok, A3, CMD3, 0.0)  # pins agent 3's session
    assert gate.admit_twist(wire.Cmd(3, 5, 0.9, 0.0), A3, CMD3, 0.0)  # ROS 2: several a tick, no conflict
    assert not gate.admit_twist(ok, X, CMD3, 0.1)  # another session: impersonation
    assert not gate.admit_twist(wire.Cmd(3, 5, 1.0e5, 0.0), A3, CMD3, 0.2)  # above the planner's bound
    rows = {(kind, src): n for kind, src, n, _t in gate.tally.as_rows()}
    assert rows == {("impersonation", X): 1, ("command", A3): 1}


@pytest.mark.parametrize("v, omega", [(1.7e308, 0.0), (0.0, -1.7e308), (2e9, 0.0), (math.inf, 0.0), (math.nan, 1.0)])
def test_absurd_twists_are_refused_at_decode(v: float, omega: float) -> None:
    store = ros2._store()
    vec = store.types["geometry_msgs/msg/Vector3"]
    raw = bytes(store.serialize_cdr(store.types[ros2.TWIST](linear=vec(v, 0.0, 0.0), angular=vec(0.0, 0.0, omega)),
                                    ros2.TWIST, little_endian=True))
    with pytest.raises(ros2.Ros2Error):
        ros2.twist_from_ros(raw)


def test_an_odometry_beyond_any_robot_is_refused_at_decode() -> None:
    good = ros2.odom_to_ros(ros2.Odom(3, 1.0, 5.0, 5.0, 0.3))
    assert ros2.odom_from_ros(good, 3).x_m == 5.0
    with pytest.raises(ros2.Ros2Error):
        ros2.odom_from_ros(ros2.odom_to_ros(ros2.Odom(3, 1.0, 1.3e308, -1.3e308, 0.3)), 3)


def test_may_matter_of_a_robot_at_the_float_limit_is_false_not_an_overflow() -> None:
    grid = CellGrid.for_scenario(S)
    assert grid.may_matter((0.0, 0.0), (1.0, 1.0))
    assert not grid.may_matter((1.3e308, -1.3e308), (0.0, 0.0))
    assert not grid.may_matter((-1.7e308, 0.0), (1.7e308, 0.0))


def test_two_different_commands_for_one_agents_tick_conflict() -> None:
    adm = pinned()
    key = Keys("r").host(2, "cmd")
    assert adm.check_cmd(wire.Cmd(2, 4, 1.0, 0.0), "a2", key, 0.0, world_k=4) is None
    assert adm.check_cmd(wire.Cmd(2, 4, 1.0, 0.0), "a2", key, 0.1, world_k=4) is None  # the same again: fine
    got = adm.check_cmd(wire.Cmd(2, 4, -3.0, 0.2), "a2", key, 0.2, world_k=4)  # stamped with agent 2's id
    assert got is not None and (got.kind, got.source) == (K.CONFLICT, "a2")
    assert adm.check_cmd(wire.Cmd(2, 5, -3.0, 0.2), "a2", key, 0.3, world_k=5) is None  # the next tick: its own


def test_a_token_without_data_stops_holding_a_waiting_tick_after_the_grace() -> None:
    m = Membership(Policy.world(Timing(token_confirm_s=0.0)))  # await grace 4 s
    for a in (3, 4):
        m.token(a, True, 0.0, 0.0)
    m.start(1.0, 0.0)
    m.data(3, 1.0, 0.0)
    m.data(4, 1.0, 0.0)
    # tick published at wall 2: agent 4 commands, agent 3 (dead; a forged token stands for it) never does
    m.data(4, 2.1, 0.05)
    for wall in (3.0, 5.9):
        m.awaited(3, 2.0, wall)
        assert m.alive(3, wall, 0.05)  # within the grace (sim time stands still: alive by its sim freshness)
    m.awaited(3, 2.0, 6.1)
    assert not m.alive(3, 6.1, 0.05) and m.alive(4, 6.1, 0.05)
    assert not m.alive(3, 30.0, 0.05)  # and it stays out, though sim time has not moved
    m.data(3, 31.0, 0.05)  # its data: alive again
    assert m.alive(3, 31.0, 0.05)


def test_an_agent_that_answered_is_never_muted_by_a_long_wait_for_another() -> None:
    m = Membership(Policy.world(Timing(token_confirm_s=0.0)))  # await grace 4 s
    m.token(4, True, 0.0, 0.0)
    m.start(1.0, 0.0)
    m.data(4, 2.1, 0.05)
    m.awaited(4, 2.0, 60.0)  # (it is not awaited; even if asked, its data since the wait began counts)
    assert m.alive(4, 60.0, 0.05)


def test_one_forged_message_heard_by_many_counts_once() -> None:
    rows = [{"process": p, "kind": "not_from_world", "source": X, "count": 7, "first_t": 1.0}
            for p in ("monitor", "agent-1", "agent-2")]
    rows.append({"process": "agent-2", "kind": "not_from_world", "source": "y", "count": 2, "first_t": 1.0})
    rows.append({"process": "simworld", "kind": "impersonation", "source": X, "count": 5, "first_t": 1.0})
    by_kind, by_process = distinct_intrusions(rows)
    assert by_kind == {"not_from_world": 9, "impersonation": 5}
    assert by_process == {"monitor": 7, "agent-1": 7, "agent-2": 9, "simworld": 5}
