"""The wire protocol: msgpack schemas (docs/wire.md); the key expressions are in reconswarm.net.wire.keys.

Every message is a frozen dataclass with a paired `<name>_to_wire` / `<name>_from_wire`. Decoding
validates everything a hostile or broken peer could get wrong (size, msgpack, schema version, types,
finite numbers, the agent id in the payload matching the key) and raises `WireError`; the receiver
counts and drops, it never dies.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from functools import cached_property
from typing import Any

import msgpack

from reconswarm.net.wire.keys import WireError
from reconswarm.paper.events import Event
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

VERSION = 1


# ---------------------------------------------------------------------------------------------- messages


class ClockMode(StrEnum):
    """How simworld advances: on every live agent's command (deterministic) or on wall time."""

    LOCKSTEP = "lockstep"
    REALTIME = "realtime"



@dataclass(frozen=True)
class Scan:
    id: int
    k: int
    t: float
    points: tuple[tuple[float, float, str], ...]
    # Held robots in range: (agent id, head point x, y) of robots whose agents are gone or whose commands stopped
    # (the world holds them where they stopped). With spatial cells an agent hears only its neighbourhood, so a
    # robot lost far away is known to it only once it comes near: the world's range sensing tells it.
    bodies: tuple[tuple[int, float, float], ...] = ()


@dataclass(frozen=True)
class State:
    """A robot's state at tick k and what it senses then: one message per agent per tick (`scan`: None when
    nothing is within range; in ROS 2 mode the state comes as odometry and the scan on its own key)."""

    id: int
    k: int
    t: float
    x: float  # body centre s
    y: float
    theta: float
    px: float  # head point p
    py: float
    scan: Scan | None = None


@dataclass(frozen=True)
class Cmd:
    """The agent's command of tick k as the unicycle's own inputs (what a robot base and ROS 2's Twist take):
    [v, ω] = M(θ_k)⁻¹ u, eq. 3 inverted at the heading of the state it planned from."""

    id: int
    k: int
    v_mps: float
    omega_radps: float


@dataclass(frozen=True)
class Beacon:
    id: int
    k: int
    t: float
    px: float
    py: float
    radius: float
    rev: int = 0  # revision of the sender's obstacle set at tick k-1 (its counters go in its report)


@dataclass(frozen=True)
class ObstacleSet:
    id: int
    k: int
    rev: int
    obstacles: dict[str, tuple[tuple[float, float], ...]] = field(default_factory=dict)


@dataclass(frozen=True)
class Clock:
    k: int
    t: float
    alive: tuple[int, ...]
    mode: ClockMode = ClockMode.LOCKSTEP
    speed: float = 0.0  # realtime: simulated seconds per wall second
    end: bool = False
    reason: str = ""
    rejected: int = 0  # messages simworld has rejected so far
    stats: dict[str, float] = field(default_factory=dict)  # final realtime statistics

    @cached_property
    def alive_set(self) -> frozenset[int]:
        """`alive` as a set, built once per clock (a host hands one clock to each of its agents)."""
        return frozenset(self.alive)


@dataclass(frozen=True)
class Truth:
    """Every robot's state at tick k in one message (simworld -> monitor)."""

    k: int
    t: float
    ids: tuple[int, ...]
    x: tuple[float, ...]
    y: tuple[float, ...]
    theta: tuple[float, ...]
    px: tuple[float, ...]
    py: tuple[float, ...]


# ------------------------------------------------------------------------------------------- encode


def _pack(obj: dict[str, Any]) -> bytes:
    return msgpack.packb({"v": VERSION, **obj}, use_bin_type=True)


def state_to_wire(m: State) -> bytes:
    d: dict[str, Any] = {"id": m.id, "k": m.k, "t": m.t, "x": m.x, "y": m.y, "theta": m.theta, "px": m.px,
                         "py": m.py}
    if m.scan is not None:
        _scan_fields(d, m.scan)
    return _pack(d)


def _scan_fields(d: dict[str, Any], m: Scan) -> None:
    d["points"] = m.points  # (msgpack packs a tuple as the array a list is: the same bytes, no copy)
    if m.bodies:
        d["bodies"] = m.bodies


def scan_to_wire(m: Scan) -> bytes:
    d: dict[str, Any] = {"id": m.id, "k": m.k, "t": m.t}
    _scan_fields(d, m)
    return _pack(d)


def cmd_to_wire(m: Cmd) -> bytes:
    return _pack({"id": m.id, "k": m.k, "v_mps": m.v_mps, "omega_radps": m.omega_radps})


def beacon_to_wire(m: Beacon) -> bytes:
    return _pack({"id": m.id, "k": m.k, "t": m.t, "px": m.px, "py": m.py, "radius": m.radius, "rev": m.rev})


def obstacles_to_wire(m: ObstacleSet) -> bytes:
    return _pack({"id": m.id, "k": m.k, "rev": m.rev,
                  "obstacles": {oid: [[x, y] for x, y in pts] for oid, pts in m.obstacles.items()}})


def clock_to_wire(m: Clock) -> bytes:
    return _pack({"k": m.k, "t": m.t, "alive": list(m.alive), "mode": str(m.mode), "speed": m.speed, "end": m.end,
                  "reason": m.reason, "rejected": m.rejected, "stats": m.stats})


def truth_to_wire(m: Truth) -> bytes:
    return _pack({"k": m.k, "t": m.t, "ids": list(m.ids), "x": list(m.x), "y": list(m.y), "theta": list(m.theta),
                  "px": list(m.px), "py": list(m.py)})


def event_to_wire(m: Event) -> bytes:
    """The event exactly as the monitor records it (Event.to_dict), with the wire version."""
    return _pack(m.to_dict())


# ------------------------------------------------------------------------------------------- decode


def _unpack(payload: bytes) -> dict[str, Any]:
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise WireError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD_BYTES}")
    try:
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=True,
                              max_array_len=MAX_ARRAY_LEN, max_map_len=MAX_MAP_LEN,
                              max_str_len=MAX_STR_BYTES, max_bin_len=0, max_ext_len=0)
    except Exception as exc:  # msgpack raises several unrelated exception types
        raise WireError(f"undecodable payload: {type(exc).__name__}") from None
    if not isinstance(obj, dict):
        raise WireError("payload is not a map")
    if obj.get("v") != VERSION:
        raise WireError(f"schema version {obj.get('v')!r}, expected {VERSION}")
    return obj


def _int(obj: dict[str, Any], key: str, lo: int = 0, hi: int = 2**53, default: int | None = None) -> int:
    v = obj.get(key, default)
    if type(v) is not int:  # excludes bool, a subclass of int
        raise WireError(f"field {key!r}: expected an integer")
    if not lo <= v <= hi:
        raise WireError(f"field {key!r}: {v} out of range")
    return v


def _num(v: Any, what: str) -> float:
    t = type(v)
    if t is float:
        if v - v == 0.0:  # false for NaN and ±inf
            return float(v)
        raise WireError(f"{what}: not finite")
    if t is int:
        return float(v)
    raise WireError(f"{what}: expected a number")


def _float(obj: dict[str, Any], key: str) -> float:
    v = obj.get(key)
    if type(v) is float and v - v == 0.0:  # the common case, checked inline
        return float(v)
    if v is None:
        raise WireError(f"field {key!r} missing")
    return _num(v, f"field {key!r}")


def _str(v: Any, what: str) -> str:
    if not isinstance(v, str) or not v or len(v) > MAX_STR:
        raise WireError(f"{what}: expected a short string")
    return v


def _agent_id(obj: dict[str, Any], key_id: int | None) -> int:
    aid = _int(obj, "id", 0, MAX_AGENT_ID)
    if key_id is not None and aid != key_id:
        raise WireError(f"payload claims agent {aid} on agent {key_id}'s key")
    return aid


def state_from_wire(payload: bytes, key_id: int | None = None) -> State:
    o = _unpack(payload)
    aid, k, t = _agent_id(o, key_id), _int(o, "k"), _float(o, "t")
    scan = Scan(aid, k, t, _points(o), _bodies(o.get("bodies", []))) if "points" in o or "bodies" in o else None
    return State(aid, k, t, _float(o, "x"), _float(o, "y"), _float(o, "theta"), _float(o, "px"), _float(o, "py"),
                 scan)


def scan_from_wire(payload: bytes, key_id: int | None = None) -> Scan:
    o = _unpack(payload)
    return Scan(_agent_id(o, key_id), _int(o, "k"), _float(o, "t"), _points(o), _bodies(o.get("bodies", [])))


def _points(o: dict[str, Any]) -> tuple[tuple[float, float, str], ...]:
    pts = o.get("points")
    if not isinstance(pts, list) or len(pts) > MAX_POINTS:
        raise WireError(f"field 'points': expected a list of at most {MAX_POINTS} points")
    out = []
    for p in pts:
        if type(p) is not list or len(p) != 3:
            raise WireError("field 'points': each point is [x, y, obstacle_id]")
        x, y, oid = p
        # Inline for the common case (two finite floats and a short name); the helpers say what is wrong.
        if not (type(x) is float and type(y) is float and x - x == 0.0 and y - y == 0.0):
            x, y = _num(x, "point x"), _num(y, "point y")
        if type(oid) is not str or not 0 < len(oid) <= MAX_STR:
            _str(oid, "point obstacle_id")
        out.append((x, y, oid))
    return tuple(out)


def _bodies(raw: Any) -> tuple[tuple[int, float, float], ...]:
    if not isinstance(raw, list) or len(raw) > MAX_POINTS:
        raise WireError("field 'bodies': expected a list of [agent_id, x, y]")
    out = []
    for b in raw:
        if type(b) is not list or len(b) != 3 or type(b[0]) is not int or not 0 <= b[0] <= MAX_AGENT_ID:
            raise WireError("field 'bodies': each body is [agent_id, x, y]")
        out.append((b[0], _num(b[1], "body x"), _num(b[2], "body y")))
    return tuple(out)


def cmd_from_wire(payload: bytes, key_id: int | None = None) -> Cmd:
    o = _unpack(payload)
    return Cmd(_agent_id(o, key_id), _int(o, "k"), _float(o, "v_mps"), _float(o, "omega_radps"))


def beacon_from_wire(payload: bytes, key_id: int | None = None) -> Beacon:
    o = _unpack(payload)
    radius = _float(o, "radius")
    if radius <= 0:
        raise WireError("field 'radius': must be > 0")
    return Beacon(_agent_id(o, key_id), _int(o, "k"), _float(o, "t"), _float(o, "px"), _float(o, "py"), radius,
                  _int(o, "rev", 0, 2**53, 0))


def obstacles_from_wire(payload: bytes, key_id: int | None = None) -> ObstacleSet:
    o = _unpack(payload)
    sets = o.get("obstacles")
    if not isinstance(sets, dict) or len(sets) > MAX_OBSTACLES:
        raise WireError("field 'obstacles': expected a map of obstacle id to vertices")
    out: dict[str, tuple[tuple[float, float], ...]] = {}
    for oid, pts in sets.items():
        name = _str(oid, "obstacle id")
        if not isinstance(pts, list) or not pts or len(pts) > MAX_VERTICES:
            raise WireError(f"obstacle {name!r}: expected 1..{MAX_VERTICES} vertices")
        verts = []
        for p in pts:
            if not isinstance(p, list) or len(p) != 2:
                raise WireError(f"obstacle {name!r}: each vertex is [x, y]")
            verts.append((_num(p[0], "vertex x"), _num(p[1], "vertex y")))
        out[name] = tuple(verts)
    return ObstacleSet(_agent_id(o, key_id), _int(o, "k"), _int(o, "rev"), out)


def clock_from_wire(payload: bytes) -> Clock:
    o = _unpack(payload)
    alive = o.get("alive")
    if not isinstance(alive, list) or len(alive) > MAX_IDS:
        raise WireError("field 'alive': expected a list of agent ids")
    ids = tuple(_int({"id": a}, "id", 0, MAX_AGENT_ID) for a in alive)
    try:
        mode = ClockMode(o.get("mode", "lockstep"))
    except ValueError:
        raise WireError(f"field 'mode': unknown clock mode {o.get('mode')!r}") from None
    end = o.get("end", False)
    if not isinstance(end, bool):
        raise WireError("field 'end': expected a boolean")
    reason = o.get("reason", "")
    if not isinstance(reason, str) or len(reason) > MAX_REASON:
        raise WireError("field 'reason': expected a short string")
    stats_raw = o.get("stats", {})
    if not isinstance(stats_raw, dict) or len(stats_raw) > MAX_STATS:
        raise WireError("field 'stats': expected a small map")
    stats = {_str(k, "stats key"): _num(v, f"stats {k!r}") for k, v in stats_raw.items()}
    speed = _num(o.get("speed", 0.0), "field 'speed'")
    if speed < 0:
        raise WireError("field 'speed': must be >= 0")
    return Clock(_int(o, "k"), _float(o, "t"), ids, mode, speed, end, reason, _int(o, "rejected", 0, 2**53, 0), stats)


def truth_from_wire(payload: bytes) -> Truth:
    o = _unpack(payload)
    ids = o.get("ids")
    if not isinstance(ids, list) or len(ids) > MAX_IDS:
        raise WireError("field 'ids': expected a list of agent ids")
    n = len(ids)
    cols = []
    for key in ("x", "y", "theta", "px", "py"):
        col = o.get(key)
        if not isinstance(col, list) or len(col) != n:
            raise WireError(f"field {key!r}: expected {n} numbers")
        cols.append(tuple(_num(v, f"field {key!r}") for v in col))
    return Truth(_int(o, "k"), _float(o, "t"), tuple(_int({"id": a}, "id", 0, MAX_AGENT_ID) for a in ids), *cols)


def event_from_wire(payload: bytes) -> Event:
    o = _unpack(payload)
    o.pop("v", None)
    _str(o.get("kind"), "field 'kind'")
    for key in ("before", "after"):
        g = o.get(key, [])
        if not isinstance(g, list) or not all(isinstance(x, list) for x in g):
            raise WireError(f"field {key!r}: expected a list of groups")
        for grp in g:
            for a in grp:
                _int({"id": a}, "id", 0, MAX_AGENT_ID)
    if "agent" in o:
        _int(o, "agent", 0, MAX_AGENT_ID)
    _event_values(o)
    try:
        return Event.from_dict(o)
    except (KeyError, TypeError, ValueError) as exc:
        raise WireError(f"event: {exc}") from None


def _event_values(o: dict[str, Any]) -> None:
    """An event's time and, when set, its other times are finite numbers and its cause a short string
    (Event.from_dict alone would take "1.5", true or NaN as a time and any value as the cause)."""
    _float(o, "t")
    for key in ("t_confirmed", "duration_s", "wall_unix"):
        if key in o:
            _num(o[key], f"field {key!r}")
    if "cause" in o:
        _str(o["cause"], "field 'cause'")
