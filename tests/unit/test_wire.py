"""The wire module: every message round-trips exactly, and every decoder rejects what it must."""

from __future__ import annotations

import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.paper.events import Event, EventKind
from reconswarm.scenario.wire_limits import MAX_AGENT_ID, MAX_PAYLOAD_BYTES

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
ids = st.integers(min_value=0, max_value=MAX_AGENT_ID)
ticks = st.integers(min_value=0, max_value=2**40)
names = st.text(alphabet="abcdefghijklmnopqrstuvwxyz0123456789-_", min_size=1, max_size=20)


@settings(max_examples=150, deadline=None)
@given(ids, ticks, finite, finite, finite, finite, finite, finite)
def test_state_round_trip(aid, k, t, x, y, th, px, py):
    m = wire.State(aid, k, t, x, y, th, px, py)
    assert wire.state_from_wire(wire.state_to_wire(m), aid) == m
    assert not {"points", "bodies"} & msgpack.unpackb(wire.state_to_wire(m)).keys()  # nothing sensed: no scan


@settings(max_examples=100, deadline=None)
@given(ids, ticks, finite, finite, finite, st.lists(st.tuples(finite, finite, names), max_size=30),
       st.lists(st.tuples(ids, finite, finite), max_size=5))
def test_state_carries_its_scan_in_the_same_message(aid, k, t, px, py, pts, bodies):
    scan = wire.Scan(aid, k, t, tuple(pts), tuple(bodies))
    m = wire.State(aid, k, t, px - 0.5, py, 0.0, px, py, scan)
    assert wire.state_from_wire(wire.state_to_wire(m), aid) == m
    # the scan inside a state is the scan message's fields under the state's id, k and t
    alone = msgpack.unpackb(wire.scan_to_wire(scan))
    inside = msgpack.unpackb(wire.state_to_wire(m))
    assert {f: inside[f] for f in alone} == alone


@pytest.mark.parametrize("fields", [{"points": "x"}, {"points": [[1.0, 2.0]]}, {"bodies": [[1, 2.0, 3.0]]},
                                    {"points": [], "bodies": [[1, 2.0]]}, {"points": [[1.0, 2.0, 7]]}])
def test_a_state_with_a_malformed_scan_is_refused(fields):
    payload = wire._pack({"id": 3, "k": 1, "t": 0.05, "x": 0.0, "y": 0.0, "theta": 0.0, "px": 0.5, "py": 0.0,
                          **fields})
    with pytest.raises(WireError, match=r"point|bodies|body"):
        wire.state_from_wire(payload, 3)


@settings(max_examples=100, deadline=None)
@given(ids, ticks, finite, st.lists(st.tuples(finite, finite, names), max_size=50))
def test_scan_round_trip(aid, k, t, pts):
    m = wire.Scan(aid, k, t, tuple(pts))
    assert wire.scan_from_wire(wire.scan_to_wire(m), aid) == m


@settings(max_examples=100, deadline=None)
@given(ids, ticks, finite, st.lists(st.tuples(ids, finite, finite), max_size=20))
def test_scan_round_trip_with_held_bodies(aid, k, t, bodies):
    m = wire.Scan(aid, k, t, ((1.0, 2.0, "a"),), tuple(bodies))
    assert wire.scan_from_wire(wire.scan_to_wire(m), aid) == m


@pytest.mark.parametrize("bodies", [[[1, 2.0]], [["1", 2.0, 3.0]], [[1, float("nan"), 3.0]], [[-1, 2.0, 3.0]],
                                    [[True, 2.0, 3.0]], "x", [[1, 2.0, "y"]]])
def test_malformed_held_bodies_are_refused(bodies):
    payload = wire._pack({"id": 3, "k": 1, "t": 0.05, "points": [], "bodies": bodies})
    with pytest.raises(WireError, match=r"body|bodies"):
        wire.scan_from_wire(payload, 3)


@settings(max_examples=100, deadline=None)
@given(ids, ticks, finite, finite)
def test_cmd_round_trip(aid, k, v, w):
    m = wire.Cmd(aid, k, v, w)
    assert wire.cmd_from_wire(wire.cmd_to_wire(m), aid) == m


@settings(max_examples=100, deadline=None)
@given(ids, ticks, finite, finite, finite, st.floats(min_value=1e-3, max_value=1e3), st.integers(0, 2**40))
def test_beacon_round_trip(aid, k, t, px, py, r, rev):
    m = wire.Beacon(aid, k, t, px, py, r, rev)
    assert wire.beacon_from_wire(wire.beacon_to_wire(m), aid) == m


@settings(max_examples=100, deadline=None)
@given(ids, ticks, st.integers(0, 2**40),
       st.dictionaries(names, st.lists(st.tuples(finite, finite), min_size=1, max_size=20).map(tuple), max_size=5))
def test_obstacles_round_trip(aid, k, rev, sets):
    m = wire.ObstacleSet(aid, k, rev, sets)
    assert wire.obstacles_from_wire(wire.obstacles_to_wire(m), aid) == m


@settings(max_examples=100, deadline=None)
@given(ticks, finite, st.lists(ids, max_size=30).map(tuple), st.sampled_from(["lockstep", "realtime"]),
       st.floats(min_value=0, max_value=1e3), st.booleans(), names,
       st.dictionaries(names, finite, max_size=5))
def test_clock_round_trip(k, t, alive, mode, speed, end, reason, stats):
    m = wire.Clock(k, t, alive, mode, speed, end, reason, 3, stats)
    assert wire.clock_from_wire(wire.clock_to_wire(m)) == m


@settings(max_examples=50, deadline=None)
@given(ticks, finite, st.lists(st.tuples(ids, finite, finite, finite, finite, finite), max_size=20))
def test_truth_round_trip(k, t, rows):
    cols = list(zip(*rows, strict=True)) if rows else [()] * 6
    m = wire.Truth(k, t, *(tuple(c) for c in cols))
    assert wire.truth_from_wire(wire.truth_to_wire(m)) == m


def test_event_round_trip():
    m = Event(12.5, EventKind.SPLIT, ((1, 2, 3),), ((1,), (2, 3)), None)
    assert wire.event_from_wire(wire.event_to_wire(m)) == m
    lost = Event(3.0, EventKind.AGENT_LOST, ((1, 2),), ((1,),), 2)
    assert wire.event_from_wire(wire.event_to_wire(lost)) == lost


def test_keys_parse_every_key():
    k = Keys("paper")
    assert k.parse(k.scan(3)) == ("agent", 3, "scan")
    assert k.parse(k.host(10, "cmd")) == ("host", 10, "cmd") and k.parse(k.host(3, "state")) == ("host", 3, "state")
    assert k.parse(k.host_beacons((-3, 4), 1)) == ("host", 1, "beacons")
    assert k.parse(k.obstacles((0, 12), 2)) == ("agent", 2, "obstacles")
    assert k.parse(k.scan(7)) == ("agent", 7, "scan")
    assert k.parse(k.clock) == ("clock", None, "")
    assert k.parse(k.event) == ("event", None, "")
    assert k.parse(k.truth) == ("truth", None, "")
    assert k.parse(k.alive_agent(4)) == ("alive", 4, "agent")
    assert k.parse(k.alive_simworld) == ("alive", None, "simworld")
    assert k.parse(k.alive_monitor) == ("alive", None, "monitor")
    for bad in ("swarm/other/clock", "swarm/paper/agent/x/state", "swarm/paper/agent/-1/cmd", "swarm/paper/zzz",
                "swarm/paper/agent/99999999999/cmd", "swarm/paper/cell/1-2/agent/1/beacon",
                "swarm/paper/cell/1_2/agent/1/cmd", "swarm/paper/cell/x_2/agent/1/beacon"):
        with pytest.raises(WireError):
            k.parse(bad)


def _good_beacon() -> dict:
    return {"v": 1, "id": 3, "k": 5, "t": 0.25, "px": 1.0, "py": 2.0, "radius": 2.5, "rev": 0, "rejected": 0}


@pytest.mark.parametrize("mutate, why", [
    (lambda o: o.update(v=2), "version"),
    (lambda o: o.pop("v"), "version"),
    (lambda o: o.update(id=4), "claims agent 4"),
    (lambda o: o.update(px=math.nan), "not finite"),
    (lambda o: o.update(py=math.inf), "not finite"),
    (lambda o: o.update(px="1.0"), "expected a number"),
    (lambda o: o.update(px=True), "expected a number"),
    (lambda o: o.update(k=-1), "out of range"),
    (lambda o: o.update(k=1.5), "expected an integer"),
    (lambda o: o.update(radius=0.0), "radius"),
    (lambda o: o.pop("px"), "missing"),
])
def test_beacon_rejections(mutate, why):
    o = _good_beacon()
    mutate(o)
    with pytest.raises(WireError, match=why):
        wire.beacon_from_wire(msgpack.packb(o), 3)


@pytest.mark.parametrize("payload", [b"", b"\xc1", b"\x93\x01\x02\x03", b"\xff" * 64, msgpack.packb([1, 2]),
                                     msgpack.packb("text"), msgpack.packb({1: 2}),
                                     b"\x00" * (MAX_PAYLOAD_BYTES + 1)])
def test_garbage_is_rejected_by_every_decoder(payload):
    for decode in (wire.state_from_wire, wire.scan_from_wire, wire.cmd_from_wire, wire.beacon_from_wire,
                   wire.obstacles_from_wire):
        with pytest.raises(WireError):
            decode(payload, 1)
    for decode0 in (wire.clock_from_wire, wire.event_from_wire, wire.truth_from_wire):
        with pytest.raises(WireError):
            decode0(payload)


def test_structural_rejections():
    scan = {"v": 1, "id": 1, "k": 0, "t": 0.0, "points": [[1.0, 2.0]]}
    with pytest.raises(WireError, match="each point"):
        wire.scan_from_wire(msgpack.packb(scan), 1)
    obs = {"v": 1, "id": 1, "k": 0, "rev": 1, "obstacles": {"a": [[1.0, math.nan]]}}
    with pytest.raises(WireError, match="not finite"):
        wire.obstacles_from_wire(msgpack.packb(obs), 1)
    obs["obstacles"] = {"a": []}
    with pytest.raises(WireError, match="vertices"):
        wire.obstacles_from_wire(msgpack.packb(obs), 1)
    clock = {"v": 1, "k": 0, "t": 0.0, "alive": [1, "2"]}
    with pytest.raises(WireError):
        wire.clock_from_wire(msgpack.packb(clock))
    clock = {"v": 1, "k": 0, "t": 0.0, "alive": [1], "mode": "warp"}
    with pytest.raises(WireError, match="mode"):
        wire.clock_from_wire(msgpack.packb(clock))
    truth = {"v": 1, "k": 0, "t": 0.0, "ids": [1, 2], "x": [0.0], "y": [0.0, 1.0], "theta": [0.0, 0.0],
             "px": [0.0, 0.0], "py": [0.0, 0.0]}
    with pytest.raises(WireError, match="expected 2 numbers"):
        wire.truth_from_wire(msgpack.packb(truth))
