"""Decoder rules that bench/mutation.py found no test for on reconswarm/net/wire/wire.py (the 2026-12-02 run): the
clock's optional fields and their defaults, every list and map at its bound (the bound accepted, one more
refused), the size bound at exactly 1 MiB, msgpack's own limits wherever in the payload, the agent id of a
scan, state or obstacle set against its key, and refusals that name the field (the receiver logs the reason).
A refusal is always a WireError (dropped and counted), never another exception."""

from __future__ import annotations

import math
from typing import Any

import msgpack
import pytest

from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import WireError
from reconswarm.scenario.wire_limits import (
    MAX_AGENT_ID,
    MAX_ARRAY_LEN,
    MAX_IDS,
    MAX_MAP_LEN,
    MAX_OBSTACLES,
    MAX_PAYLOAD_BYTES,
    MAX_POINTS,
    MAX_REASON,
    MAX_STATS,
    MAX_STR,
    MAX_STR_BYTES,
    MAX_VERTICES,
)


def pack(**fields: Any) -> bytes:
    return msgpack.packb({"v": 1, **fields})


def refused(decode: Any, payload: bytes, *key: int | None) -> str:
    """The WireError's text of a refused payload (a WireError and nothing else)."""
    with pytest.raises(WireError) as e:
        decode(payload, *key)
    return str(e.value)


# ------------------------------------------------------------------------------------------------ clock


def clock(**fields: Any) -> bytes:
    return pack(**{"k": 3, "t": 0.15, "alive": [1, 2], **fields})


def test_a_clock_with_only_k_t_and_alive_is_a_lockstep_tick_that_goes_on() -> None:
    c = wire.clock_from_wire(clock())
    assert (c.k, c.t, c.alive) == (3, 0.15, (1, 2))
    assert c.mode is wire.ClockMode.LOCKSTEP and c.mode == "lockstep"
    assert c.speed == 0.0 and c.end is False and c.reason == "" and c.rejected == 0 and c.stats == {}


def test_a_clocks_optional_fields_are_taken_when_given() -> None:
    c = wire.clock_from_wire(clock(mode="realtime", speed=0.5, end=True, reason="converged", rejected=7,
                                   stats={"overruns": 2}))
    assert (c.mode, c.speed, c.end, c.reason, c.rejected, c.stats) == ("realtime", 0.5, True, "converged", 7,
                                                                         {"overruns": 2.0})
    assert wire.clock_from_wire(clock(speed=0)).speed == 0.0  # stopped: allowed


@pytest.mark.parametrize("fields, why", [
    ({"alive": 5}, r"^field 'alive'"), ({"alive": "12"}, r"^field 'alive'"),
    ({"alive": [0] * (MAX_IDS + 1)}, r"^field 'alive'"),
    ({"alive": [1, MAX_AGENT_ID + 1]}, r"^field 'id': 2147483648 out of range"),
    ({"mode": "warp"}, r"^field 'mode': unknown clock mode 'warp'"),
    ({"end": 1}, r"^field 'end': expected a boolean"), ({"end": None}, r"^field 'end'"),
    ({"reason": 5}, r"^field 'reason': expected a short string"), ({"reason": None}, r"^field 'reason'"),
    ({"reason": "r" * (MAX_REASON + 1)}, r"^field 'reason'"),
    ({"stats": 5}, r"^field 'stats': expected a small map"), ({"stats": [1.0]}, r"^field 'stats'"),
    ({"stats": {f"s{i}": 1.0 for i in range(MAX_STATS + 1)}}, r"^field 'stats'"),
    ({"stats": {"": 1.0}}, r"^stats key: expected a short string"),
    ({"stats": {"s" * (MAX_STR + 1): 1.0}}, r"^stats key"),
    ({"stats": {"overruns": "2"}}, r"^stats 'overruns': expected a number"),
    ({"stats": {"overruns": math.nan}}, r"^stats 'overruns': not finite"),
    ({"speed": "fast"}, r"^field 'speed': expected a number"), ({"speed": None}, r"^field 'speed'"),
    ({"speed": -0.5}, r"^field 'speed': must be >= 0"), ({"speed": math.inf}, r"^field 'speed': not finite"),
    ({"rejected": -1}, r"^field 'rejected': -1 out of range"),
    ({"rejected": 2**53 + 1}, r"^field 'rejected'"), ({"rejected": None}, r"^field 'rejected'"),
])
def test_a_clock_field_out_of_its_bounds_is_refused_by_name(fields: dict[str, Any], why: str) -> None:
    with pytest.raises(WireError, match=why):
        wire.clock_from_wire(clock(**fields))


def test_a_clocks_bounds_themselves_are_accepted() -> None:
    assert wire.clock_from_wire(clock(alive=[0] * MAX_IDS)).alive == (0,) * MAX_IDS
    assert wire.clock_from_wire(clock(alive=[0, MAX_AGENT_ID])).alive == (0, MAX_AGENT_ID)
    assert wire.clock_from_wire(clock(reason="r" * MAX_REASON)).reason == "r" * MAX_REASON
    stats = {f"s{i}": float(i) for i in range(MAX_STATS - 1)} | {"s" * MAX_STR: 1.5}
    assert wire.clock_from_wire(clock(stats=stats)).stats == stats
    assert wire.clock_from_wire(clock(rejected=2**53)).rejected == 2**53


# ------------------------------------------------------------------------------------------- scan points


def scan(**fields: Any) -> bytes:
    return pack(**{"id": 1, "k": 0, "t": 0.0, "points": [[130.0, 0.0, "diamond"]], **fields})


@pytest.mark.parametrize("fields, why", [
    ({"points": [[0, 0, "a"]] * (MAX_POINTS + 1)}, r"^field 'points': expected a list of at most 50000"),
    ({"points": [[1.0, 2.0, "a", 3.0]]}, r"^field 'points': each point is \[x, y, obstacle_id\]"),
    ({"points": [[1.0, 2.0, ""]]}, r"^point obstacle_id: expected a short string"),
    ({"points": [[1.0, 2.0, "o" * (MAX_STR + 1)]]}, r"^point obstacle_id"),
    ({"points": [[1.0, 2.0, None]]}, r"^point obstacle_id"),
    ({"bodies": 5}, r"^field 'bodies': expected a list of \[agent_id, x, y\]"),
    ({"bodies": [[0, 0.0, 0.0]] * (MAX_POINTS + 1)}, r"^field 'bodies': expected a list"),
    ({"bodies": [[1, 2.0]]}, r"^field 'bodies': each body is \[agent_id, x, y\]"),
    ({"bodies": [[MAX_AGENT_ID + 1, 2.0, 3.0]]}, r"^field 'bodies': each body"),
    ({"bodies": [[1, "a", 3.0]]}, r"^body x: expected a number"),
    ({"bodies": [[1, 2.0, math.inf]]}, r"^body y: not finite"),
])
def test_a_malformed_scan_is_refused_by_name(fields: dict[str, Any], why: str) -> None:
    with pytest.raises(WireError, match=why):
        wire.scan_from_wire(scan(**fields), 1)
    state = {"x": 0.0, "y": 0.0, "theta": 0.0, "px": 0.5, "py": 0.0}
    with pytest.raises(WireError, match=why):  # the same scan inside a state
        wire.state_from_wire(scan(**state, **fields), 1)


def test_a_scan_at_its_bounds_is_accepted() -> None:
    s = wire.scan_from_wire(scan(points=[[0, 0, "a"]] * MAX_POINTS, bodies=[[MAX_AGENT_ID, 1, 2]] * MAX_POINTS), 1)
    assert len(s.points) == MAX_POINTS and len(s.bodies) == MAX_POINTS
    assert s.bodies[0] == (MAX_AGENT_ID, 1.0, 2.0)
    assert wire.scan_from_wire(scan(points=[[1.0, 2.0, "o" * MAX_STR], [1.0, 2.0, "p"]]), 1).points == (
        (1.0, 2.0, "o" * MAX_STR), (1.0, 2.0, "p"))


@pytest.mark.parametrize("x, y", [(130, 2.5), (2.5, 130), (130, -2)])
def test_integer_coordinates_of_a_point_arrive_as_floats_whichever_coordinate(x: Any, y: Any) -> None:
    (p,) = wire.scan_from_wire(scan(points=[[x, y, "a"]]), 1).points
    assert p == (float(x), float(y), "a") and type(p[0]) is float and type(p[1]) is float


# --------------------------------------------------------------------------------------------- obstacles


def obstacles(**fields: Any) -> bytes:
    return pack(**{"id": 2, "k": 4, "rev": 1, "obstacles": {"a": [[1.0, 2.0], [3.0, 4.0]]}, **fields})


@pytest.mark.parametrize("fields, why", [
    ({"obstacles": 5}, r"^field 'obstacles': expected a map of obstacle id to vertices"),
    ({"obstacles": [[1.0, 2.0]]}, r"^field 'obstacles'"),
    ({"obstacles": {f"o{i}": [[0, 0]] for i in range(MAX_OBSTACLES + 1)}}, r"^field 'obstacles'"),
    ({"obstacles": {"": [[0, 0]]}}, r"^obstacle id: expected a short string"),
    ({"obstacles": {"o" * (MAX_STR + 1): [[0, 0]]}}, r"^obstacle id"),
    ({"obstacles": {"a": [[0, 0]] * (MAX_VERTICES + 1)}}, r"^obstacle 'a': expected 1..4096 vertices"),
    ({"obstacles": {"a": [[1.0, 2.0, 3.0]]}}, r"^obstacle 'a': each vertex is \[x, y\]"),
    ({"obstacles": {"a": [5]}}, r"^obstacle 'a': each vertex"), ({"obstacles": {"a": ["xy"]}}, r"^obstacle 'a'"),
    ({"obstacles": {"a": [["1", 2.0]]}}, r"^vertex x: expected a number"),
    ({"obstacles": {"a": [[1.0, math.nan]]}}, r"^vertex y: not finite"),
    ({"obstacles": {"a": [[1.0, None]]}}, r"^vertex y: expected a number"),
    ({"rev": None}, r"^field 'rev'"), ({"rev": -1}, r"^field 'rev'"),
])
def test_a_malformed_obstacle_set_is_refused_by_name(fields: dict[str, Any], why: str) -> None:
    with pytest.raises(WireError, match=why):
        wire.obstacles_from_wire(obstacles(**fields), 2)


def test_an_obstacle_set_at_its_bounds_is_accepted() -> None:
    sets = {f"o{i}": [[i, 0]] for i in range(MAX_OBSTACLES)}
    assert len(wire.obstacles_from_wire(obstacles(obstacles=sets), 2).obstacles) == MAX_OBSTACLES
    hull = wire.obstacles_from_wire(obstacles(obstacles={"o" * MAX_STR: [[1, 2]] * MAX_VERTICES}), 2).obstacles
    assert hull == {"o" * MAX_STR: ((1.0, 2.0),) * MAX_VERTICES}


# ------------------------------------------------------------------------------------ agent ids and keys


STATE = {"k": 1, "t": 0.05, "x": 0.0, "y": 0.0, "theta": 0.0, "px": 0.5, "py": 0.0}


@pytest.mark.parametrize("decode, fields", [
    (wire.state_from_wire, STATE), (wire.state_from_wire, {**STATE, "points": [[1.0, 2.0, "a"]]}),
    (wire.scan_from_wire, {"k": 1, "t": 0.05, "points": []}),
    (wire.obstacles_from_wire, {"k": 1, "rev": 0, "obstacles": {}}),
    (wire.cmd_from_wire, {"k": 1, "v_mps": 0.0, "omega_radps": 0.0}),
    (wire.beacon_from_wire, {"k": 1, "t": 0.05, "px": 0.5, "py": 0.0, "radius": 1.0}),
])
def test_an_agents_message_is_its_keys_and_its_id_is_within_bounds(decode: Any, fields: dict[str, Any]) -> None:
    assert decode(pack(id=4, **fields), 4).id == 4
    assert refused(decode, pack(id=4, **fields), 2) == "payload claims agent 4 on agent 2's key"
    assert decode(pack(id=4, **fields), None).id == 4  # no key (a tool's own decoding): the payload's id
    assert decode(pack(id=MAX_AGENT_ID, **fields), None).id == MAX_AGENT_ID
    for bad in (MAX_AGENT_ID + 1, -1):
        assert refused(decode, pack(id=bad, **fields), None) == f"field 'id': {bad} out of range"


def test_a_float_field_that_is_not_a_number_is_refused_by_name() -> None:
    assert refused(wire.state_from_wire, pack(id=1, **{**STATE, "t": "soon"}), 1) == "field 't': expected a number"
    assert refused(wire.cmd_from_wire, pack(id=1, k=1, v_mps=1.0, omega_radps=True), 1) == (
        "field 'omega_radps': expected a number")
    assert refused(wire.beacon_from_wire, pack(id=1, k=1, t=0.05, px=0.5, py=0.0, radius=0.0), 1) == (
        "field 'radius': must be > 0")
    assert wire.beacon_from_wire(pack(id=1, k=1, t=0.05, px=0.5, py=0.0, radius=0.25), 1).radius == 0.25


# ------------------------------------------------------------------------------------------- truth, event


def truth(ids: list[Any], **cols: Any) -> bytes:
    n = len(ids)
    return pack(k=1, t=0.05, ids=ids, **{c: [0] * n for c in ("x", "y", "theta", "px", "py")} | cols)


def test_truth_at_its_bound_is_accepted_and_one_more_and_bad_columns_are_refused_by_name() -> None:
    assert len(wire.truth_from_wire(truth([0] * MAX_IDS)).ids) == MAX_IDS
    assert refused(wire.truth_from_wire, truth([0] * (MAX_IDS + 1))) == "field 'ids': expected a list of agent ids"
    assert refused(wire.truth_from_wire, truth([1, 2], px=[0.0, math.nan])) == "field 'px': not finite"
    assert refused(wire.truth_from_wire, truth([1, 2], theta=[0.0, "0"])) == "field 'theta': expected a number"
    assert refused(wire.truth_from_wire, truth([1, 2], y=[0.0])) == "field 'y': expected 2 numbers"


@pytest.mark.parametrize("fields, why", [
    ({"kind": ""}, "field 'kind': expected a short string"),
    ({"kind": "teleported"}, "event: 'teleported' is not a valid EventKind"),
    ({"colour": "red"}, "event: unknown event field(s) colour"),
])
def test_a_malformed_event_is_refused_saying_why(fields: dict[str, Any], why: str) -> None:
    payload = pack(**{"t": 1.0, "kind": "split", "before": [[1, 2]], "after": [[1], [2]], **fields})
    assert refused(wire.event_from_wire, payload) == why


# ------------------------------------------------------------------------------------ the payload itself


def scan_of_bytes(size: int) -> bytes:
    """A valid scan of exactly `size` bytes (30,000 points of 34 or 35 bytes: 1.02 to 1.05 MB)."""
    n = 30_000
    names = ["o" * 30] * n
    deficit = size - len(scan(points=[[0, 0, s] for s in names]))
    assert 0 <= deficit <= n
    names[:deficit] = ["o" * 31] * deficit  # one more character: one more byte (up to 31, msgpack's fixstr)
    payload = scan(points=[[0, 0, s] for s in names])
    assert len(payload) == size
    return payload


def test_a_payload_of_exactly_1_mib_is_decoded_and_one_byte_more_is_refused_before_decoding() -> None:
    assert len(wire.scan_from_wire(scan_of_bytes(MAX_PAYLOAD_BYTES), 1).points) == 30_000
    assert refused(wire.scan_from_wire, scan_of_bytes(MAX_PAYLOAD_BYTES + 1), 1) == (
        f"payload of {MAX_PAYLOAD_BYTES + 1} bytes exceeds {MAX_PAYLOAD_BYTES}")


def state_with(**extra: Any) -> bytes:
    return pack(id=1, **STATE, **extra)


def test_msgpacks_limits_hold_anywhere_in_a_payload_even_in_a_field_no_decoder_reads() -> None:
    assert wire.state_from_wire(state_with(note=[0] * MAX_ARRAY_LEN, tags={f"t{i}": 0 for i in range(MAX_MAP_LEN)},
                                           text="x" * MAX_STR_BYTES), 1).px == 0.5
    for bad in (state_with(note=[0] * (MAX_ARRAY_LEN + 1)),
                state_with(tags={f"t{i}": 0 for i in range(MAX_MAP_LEN + 1)}),
                state_with(text="x" * (MAX_STR_BYTES + 1)), state_with(blob=b"\x01"),
                state_with(ext=msgpack.ExtType(1, b"\x01")),
                msgpack.packb({"v": 1, "id": 1, **STATE} | {7: "x"}),
                state_with(tags={"a": {3: 1}})):
        assert refused(wire.state_from_wire, bad, 1).startswith("undecodable payload: ")


def test_what_is_wrong_with_a_payload_is_said() -> None:
    assert refused(wire.state_from_wire, state_with() + b"\x00", 1) == "undecodable payload: ExtraData"
    assert refused(wire.state_from_wire, msgpack.packb([1, 2]), 1) == "payload is not a map"
    assert refused(wire.state_from_wire, msgpack.packb({"v": 2}), 1) == "schema version 2, expected 1"
    assert refused(wire.clock_from_wire, msgpack.packb({"k": 1})) == "schema version None, expected 1"


@pytest.mark.parametrize("fields, why", [
    ({"t": math.nan}, "field 't': not finite"), ({"t": math.inf}, "field 't': not finite"),
    ({"t": "1.5"}, "field 't': expected a number"), ({"t": True}, "field 't': expected a number"),
    ({"t": None}, "field 't' missing"),
    ({"t_confirmed": -math.inf}, "field 't_confirmed': not finite"),
    ({"duration_s": "2"}, "field 'duration_s': expected a number"),
    ({"wall_unix": math.nan}, "field 'wall_unix': not finite"), ({"wall_unix": None}, "field 'wall_unix'"),
    ({"cause": 5}, "field 'cause': expected a short string"), ({"cause": ""}, "field 'cause'"),
    ({"cause": "c" * (MAX_STR + 1)}, "field 'cause'"),
])
def test_an_events_times_are_finite_numbers_and_its_cause_a_short_string(fields: dict[str, Any], why: str) -> None:
    """NaN or ±inf anywhere is refused (docs/wire.md, Validation), and so are wrong types: an event's times
    are not converted from strings or booleans, its cause not from a number."""
    payload = pack(**{"t": 1.0, "kind": "split", "before": [[1, 2]], "after": [[1], [2]], **fields})
    assert refused(wire.event_from_wire, payload).startswith(why)


def test_an_events_optional_fields_are_taken_as_sent() -> None:
    e = wire.event_from_wire(pack(t=3, kind="split", before=[[1, 2]], after=[[1], [2]], cause="network",
                                  t_confirmed=4.0, duration_s=1, wall_unix=1.8e9))
    assert (e.t, e.cause, e.t_confirmed, e.duration_s, e.wall_unix) == (3.0, "network", 4.0, 1.0, 1.8e9)
    assert type(e.t) is float and type(e.duration_s) is float


def test_a_clocks_alive_set_is_its_alive_list_and_changes_nothing_else() -> None:
    c = wire.clock_from_wire(wire.clock_to_wire(wire.Clock(3, 0.15, (4, 1, 9))))
    assert c.alive_set == frozenset({1, 4, 9}) and c.alive_set is c.alive_set  # (built once)
    assert c == wire.Clock(3, 0.15, (4, 1, 9)) and wire.clock_from_wire(wire.clock_to_wire(c)) == c
