"""Scan points that are not finite (NaN, ±inf) are refused by the decoder: the message is dropped and counted,
never believed. The agent's own session decodes its state and scan through it, so a non-finite point never
reaches the agent's hull or the obstacle set it shares with its neighbours."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
import zenoh

from agent.hosted import HostedAgent, decode_sample
from agent.robot_io import take_states
from reconswarm.net.node import Invalid
from reconswarm.net.runtime.inbox import Rejections
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.hostwire import STATE_ROW, state_batch_from_wire, state_batches
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.scenario.model import load
from tests.support import PAPER, free_port
from tests.unit.solo import SoloNode

BAD = [math.nan, math.inf, -math.inf]


def _state_fields(points: list[list[Any]]) -> dict[str, Any]:
    return {"id": 1, "k": 0, "t": 0.0, "x": 99.5, "y": 0.0, "theta": 0.0, "px": 100.0, "py": 0.0, "points": points}


@pytest.mark.parametrize("bad", BAD)
@pytest.mark.parametrize("where", [0, 1])  # x or y
@pytest.mark.parametrize("at", [0, 2])  # the first point, or one after good ones
def test_a_non_finite_scan_point_is_refused_in_a_scan_and_in_a_state(bad: float, where: int, at: int) -> None:
    points: list[list[Any]] = [[130.0, 0.0, "diamond"], [131.0, 1.0, "diamond"], [132.0, 2.0, "diamond"]]
    points[at][where] = bad
    scan = {"id": 1, "k": 0, "t": 0.0, "points": points}
    with pytest.raises(WireError, match=f"point {'xy'[where]}: not finite"):
        wire.scan_from_wire(wire._pack(scan), 1)
    with pytest.raises(WireError, match=f"point {'xy'[where]}: not finite"):
        wire.state_from_wire(wire._pack(_state_fields(points)), 1)
    with pytest.raises(WireError, match=f"point {'xy'[where]}: not finite"):
        state_batch_from_wire(wire._pack({"host": 1, "k": 0, "t": 0.0, "n": 1, "scans": [[0, points, []]],
                                          "rows": STATE_ROW.pack(1, 0.0, 0.0, 0.0, 0.0, 0.0)}), 1)


def test_non_finite_points_of_both_coordinates_and_integers_are_told_apart() -> None:
    """Integers are numbers (msgpack may carry 130.0 as 130); NaN in both coordinates names x first."""
    ok = wire.scan_from_wire(wire._pack({"id": 1, "k": 0, "t": 0.0, "points": [[130, -2, "a"]]}), 1)
    assert ok.points == ((130.0, -2.0, "a"),) and all(type(v) is float for v in ok.points[0][:2])
    with pytest.raises(WireError, match="point x: not finite"):
        wire.scan_from_wire(wire._pack({"id": 1, "k": 0, "t": 0.0, "points": [[math.nan, math.inf, "a"]]}), 1)
    with pytest.raises(WireError, match="point y: expected a number"):
        wire.scan_from_wire(wire._pack({"id": 1, "k": 0, "t": 0.0, "points": [[1.0, None, "a"]]}), 1)


# ------------------------------------------------------------------------- through the agent's own session

S = load(PAPER)
A = 1
S1 = dataclasses.replace(S, agents=tuple(dataclasses.replace(a, start_m=(99.5, 0.0)) if a.id == A else a
                                         for a in S.agents))
WORLD = "world-session"


@pytest.fixture
def link() -> Any:
    port = free_port()
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{port}",), "peer").config())  # alone: nothing to connect to
    node = SoloNode(S1, A, 0.0)
    lk = HostedAgent(node, Keys("nan-test"), z, Rejections(f"agent-{A}"), Gate(S1, f"agent-{A}"))
    try:
        yield lk
    finally:
        lk.close()
        z.close()


def _finite_sets(out: list[Any]) -> list[wire.ObstacleSet]:
    sets = [o for o in out if isinstance(o, wire.ObstacleSet)]
    for m in sets:
        for verts in m.obstacles.values():
            assert all(math.isfinite(x) and math.isfinite(y) for x, y in verts), m
    return sets


def take(link: Any, payload: bytes, at_s: float) -> Any:
    """The agent's state out of its host's batch of one, as its host takes it apart (agent/robot_io.py)."""
    key = link.keys.host(A, "state")
    batches: dict[int, list[Any]] = {A: []}
    take_states(decode_sample(link.keys, key, payload, "PUT"), key, WORLD, at_s, {A: link}, {A}, link.gate, batches)
    (got,) = batches[A]
    return got


@pytest.mark.parametrize("bad", BAD)
def test_the_agent_drops_and_counts_a_state_with_a_non_finite_point_and_keeps_its_hull_finite(link: Any,
                                                                                                bad: float) -> None:
    keys, node = link.keys, link.node
    clock = link.decode(keys.clock, wire.clock_to_wire(wire.Clock(0, 0.0, (A,))), "PUT", WORLD, 0.0)
    assert isinstance(clock, wire.Clock)  # the world's session is pinned by its first clock
    poisoned = [[130.0, 0.0, "diamond"], [bad, 1.0, "diamond"], [131.0, bad, "diamond"]]
    rows = STATE_ROW.pack(A, 99.5, 0.0, 0.0, 100.0, 0.0)
    got = take(link, wire._pack({"v": wire.VERSION, "host": A, "k": 0, "t": 0.0, "n": 1, "rows": rows,
                                 "scans": [[0, poisoned, []]]}), 0.0)
    assert isinstance(got, Invalid) and "not finite" in got.reason
    assert link.rej.count == 1  # dropped and counted
    out = node.step([clock, got], 0.0)
    assert not [o for o in out if isinstance(o, wire.Cmd)]  # nothing believed: no state at tick 0 yet
    assert node.brain.known.hulls == {}
    # The world's real state of tick 0 (finite) is taken; the hull and the shared set hold only its points.
    good = wire.State(A, 0, 0.0, 99.5, 0.0, 0.0, 100.0, 0.0,
                      wire.Scan(A, 0, 0.0, ((130.0, 0.0, "diamond"), (131.0, 1.0, "diamond"), (130.5, 3.0, "diamond"))))
    st = take(link, state_batches(A, [good])[0][0], 0.01)
    assert st == good
    out = node.step([st], 0.01)
    assert [o.k for o in out if isinstance(o, wire.Cmd)] == [0]
    hull = node.brain.known.hulls["diamond"]
    assert np.isfinite(hull).all() and {tuple(v) for v in hull.tolist()} == {(130.0, 0.0), (131.0, 1.0), (130.5, 3.0)}
    assert all(np.isfinite(h).all() for h in node.brain.obstacle_sets().values())
    assert len(_finite_sets(out)) == 1  # shared with the neighbours: finite
    assert link.rej.count == 1
