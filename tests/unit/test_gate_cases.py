"""A process's gate (reconswarm/net/trust/gate.py): each kind of message goes through its own admission rule, and a
refusal is counted under its kind and source, logged with its key (the first of each kind and source at once,
then at most a line a second with how many were held back), and reported."""

from __future__ import annotations

import logging

import pytest

from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.net.wire.report import Report
from reconswarm.scenario.model import load
from tests.support import PAPER, beacon
from tests.unit.test_admission import clock

S = load(PAPER)
KEYS = Keys("paper-0a1b2c")
WORLD, A2, X = "world-zid", "agent2-zid", "intruder-zid"
DT = S.meta.dt_s


def _beacon(aid: int, k: int = 0) -> wire.Beacon:
    return beacon(aid, k, 40.0, 0.0, float(S.radii[S.agent_index(aid)]) if aid in S.ids else 1.0, DT)


def _state(k: int) -> wire.State:
    return wire.State(2, k, k * DT, 40.0, 0.0, 0.0, 41.0, 0.0, None)


def _rows(g: Gate) -> dict[tuple[str, str], tuple[int, float]]:
    return {(kind, source): (n, t) for kind, source, n, t in g.tally.as_rows()}


@pytest.fixture
def logged(caplog: pytest.LogCaptureFixture) -> pytest.LogCaptureFixture:
    caplog.set_level(logging.WARNING, logger="reconswarm.admission")
    return caplog


def test_each_kind_of_message_meets_its_own_rule(logged: pytest.LogCaptureFixture) -> None:
    g = Gate(S, "agent-5")
    assert g.admit(clock(0), WORLD, KEYS.clock, 0.0)  # pins the world's session
    assert g.admit(clock(3), WORLD, KEYS.clock, 0.1) and (g.world_k, g.t) == (3, 3 * DT)
    assert g.admit(clock(1), WORLD, KEYS.clock, 0.2) and (g.world_k, g.t) == (3, 3 * DT)  # (the newest stays)
    assert not g.admit(clock(4), X, KEYS.clock, 0.3)
    sk = KEYS.host(2, "state")
    assert not g.admit(_state(3), X, sk, 0.3) and g.admit(_state(3), WORLD, sk, 0.3)
    assert not g.admit(_beacon(999), X, KEYS.host_beacons((0, 0), 999), 0.4)
    assert g.admit(_beacon(2), A2, KEYS.host_beacons((0, 0), 2), 0.4)  # pins agent 2's session
    assert not g.admit(_beacon(2), X, KEYS.host_beacons((0, 0), 2), 0.5)
    assert not g.admit(wire.Cmd(2, 4, 1.0, 0.0), A2, KEYS.host(2, "cmd"), 0.5)  # tick 4 is not out yet (newest: 3)
    assert g.admit(wire.Cmd(2, 3, 1.0, 0.0), A2, KEYS.host(2, "cmd"), 0.5)
    assert not g.admit(wire.Cmd(2, 3, 1.0, 0.0), X, KEYS.host(2, "cmd"), 0.6)
    assert not g.admit(wire.ObstacleSet(2, 3, 1, {"no-such-obstacle": ((0.0, 0.0),)}), X,
                       KEYS.obstacles((0, 0), 2), 0.6)
    assert g.admit(wire.ObstacleSet(2, 3, 1, {}), X, KEYS.obstacles((0, 0), 2), 0.6)  # its content decides
    assert not g.admit(Report("agent-2", None), X, KEYS.report("agent-2"), 0.7)
    assert g.admit(Report("agent-2", None), A2, KEYS.report("agent-2"), 0.7)
    assert not g.admit(Report("simworld", None), X, KEYS.report("simworld"), 0.7)
    assert g.admit(Report("simworld", None), WORLD, KEYS.report("simworld"), 0.7)
    assert _rows(g) == {("not_from_world", X): (2, 3 * DT), ("unknown_agent", X): (1, 3 * DT),
                        ("impersonation", X): (4, 3 * DT), ("command", A2): (1, 3 * DT),
                        ("unknown_obstacle", X): (1, 3 * DT)}
    assert g.count == 9
    # Each first refusal of a kind and source is one line naming the process, the source, the key and why.
    assert [line.split(": ")[2].split(" on ")[1] for line in logged.messages] == [
        KEYS.clock, KEYS.host_beacons((0, 0), 999), KEYS.host_beacons((0, 0), 2), KEYS.host(2, "cmd"),
        KEYS.obstacles((0, 0), 2)]
    assert logged.messages[3] == (f"agent-5: intrusion refused: command from {A2} on {KEYS.host(2, 'cmd')}: "
                                  "command for tick 4, newest tick is 3 [total 5]")


def test_an_obstacle_set_too_large_for_the_run_is_refused_undecoded(logged: pytest.LogCaptureFixture) -> None:
    g = Gate(S, "agent-5")
    largest = g.adm.max_set_bytes
    assert g.admit_set_bytes(largest, X, KEYS.obstacles((0, 0), 2), 0.0)
    assert not g.admit_set_bytes(largest + 1, X, KEYS.obstacles((0, 0), 2), 0.0)
    assert not g.admit_set_bytes(largest + 1, X, KEYS.obstacles((0, 0), 2), 0.5)  # (held back: within 1 s)
    assert _rows(g) == {("oversize", X): (2, 0.0)} and len(logged.messages) == 1  # (before any clock: at t = 0)
    assert f"from {X} on {KEYS.obstacles((0, 0), 2)}: an obstacle set of {largest + 1} bytes" in logged.messages[0]


def test_a_cmd_vel_beyond_the_bound_is_refused_with_its_key(logged: pytest.LogCaptureFixture) -> None:
    g = Gate(S, "simworld")
    assert g.admit(clock(2), WORLD, KEYS.clock, 0.0)
    topic = "0/robot_2/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_0"
    assert g.admit_twist(wire.Cmd(2, 2, 1.0, 0.0), A2, topic, 0.0)
    assert not g.admit_twist(wire.Cmd(2, 2, 1e6, 0.0), A2, topic, 5.0)
    assert not g.admit_twist(wire.Cmd(2, 2, 1e6, 0.0), A2, topic, 5.5)
    assert _rows(g) == {("command", A2): (2, 2 * DT)} and len(logged.messages) == 1
    assert f"on {topic}: |u| = 1e+06 m/s above the bound" in logged.messages[0]


def test_a_report_or_a_state_from_the_wrong_session_is_logged_with_its_key(logged: pytest.LogCaptureFixture) -> None:
    g = Gate(S, "monitor")
    assert g.admit(clock(0), WORLD, KEYS.clock, 0.0) and g.admit(_beacon(2), A2, KEYS.host_beacons((0, 0), 2), 0.0)
    assert not g.admit(Report("agent-2", None), X, KEYS.report("agent-2"), 0.1)
    assert not g.admit(_state(0), X, KEYS.host(2, "state"), 0.2)
    assert [m.split(" on ")[1].split(": ")[0] for m in logged.messages] == [KEYS.report("agent-2"),
                                                                            KEYS.host(2, "state")]


def test_refusals_are_logged_at_most_once_a_second_with_the_held_back(logged: pytest.LogCaptureFixture) -> None:
    g = Gate(S, "agent-5")
    assert g.admit(clock(0), WORLD, KEYS.clock, 0.0)
    why = f"not_from_world from {X} on {KEYS.clock}: the world speaks from session {WORLD}"
    for now in (10.0, 10.5, 10.9, 11.0, 11.5):
        assert not g.admit(clock(1), X, KEYS.clock, now)
    assert logged.messages == [f"agent-5: intrusion refused: {why} [total 1]",  # the first at once
                     f"agent-5: intrusion refused: {why} (+2 more since the last line) [total 4]"]  # 1.0 s on
    # A new kind or source is logged at once, with what was held back since the last line.
    assert not g.admit(_beacon(999), X, KEYS.host_beacons((0, 0), 999), 11.6)
    on = KEYS.host_beacons((0, 0), 999)
    assert logged.messages[2] == (f"agent-5: intrusion refused: unknown_agent from {X} on {on}: "
                        "agent 999 is not in the scenario (+1 more since the last line) [total 6]")


def test_the_report_carries_the_tally_when_it_changed_at_most_once_a_second() -> None:
    g = Gate(S, "simworld")
    assert g.report(0.0) is None  # nothing refused yet
    g.admit(clock(0), WORLD, KEYS.clock, 0.0)
    assert not g.admit(clock(1), X, KEYS.clock, 0.0)
    assert g.report(0.0) == Report("simworld", (("not_from_world", X, 1, 0.0),), 0, -1)
    assert not g.admit(clock(1), X, KEYS.clock, 0.5)
    assert g.report(0.5) is None and g.report(0.99) is None
    assert g.report(1.0) == Report("simworld", (("not_from_world", X, 2, 0.0),), 0, -1)  # 1.0 s on: due
    assert g.report(1.5) is None  # unchanged
    assert not g.admit(clock(1), X, KEYS.clock, 1.6)
    assert g.report(1.7, final=True) == Report("simworld", (("not_from_world", X, 3, 0.0),), 0, -1)


def test_odometry_comes_from_the_world_and_within_reach_of_the_last(logged: pytest.LogCaptureFixture) -> None:
    g = Gate(S, "agent-2")
    topic = "0/robot_2/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_0"
    assert g.admit(clock(0), WORLD, KEYS.clock, 0.0)
    assert g.admit_odometry(_state(0), WORLD, topic, 0.0)
    assert not g.admit_odometry(_state(1), X, topic, 0.1)  # not the world's session
    late = wire.State(2, 2000, 2000 * DT, 40.0, 0.0, 0.0, 41.0, 0.0, None)  # (t = 100 s: anywhere near is reachable)
    far = wire.State(2, 2001, 2001 * DT, 540.0, 0.0, 0.0, 541.0, 0.0, None)  # but not 500 m in one tick
    assert g.admit(clock(2000), WORLD, KEYS.clock, 0.1)  # (the receiver's clock: odometry's time is no later)
    assert g.admit_odometry(late, WORLD, topic, 0.1)
    assert not g.admit_odometry(far, WORLD, topic, 0.1)
    assert not g.admit_odometry(far, WORLD, topic, 0.2)
    assert _rows(g) == {("not_from_world", X): (1, 0.0), ("position", WORLD): (2, 100.0)}
    assert [m.split(" on ")[1].split(": ")[0] for m in logged.messages] == [topic, topic]
    assert "odometry moved 500 m in 0.05 s" in logged.messages[1]
