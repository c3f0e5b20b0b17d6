"""One message per agent host and tick each way: its agents' states from the world, their commands to it (docs/wire.md).

An agent host (`reconswarm agent --ids ...`; a lone agent is a host of one) has the id `hid`, its lowest agent id.
The world puts each tick's states of the host's agents as one `StateBatch` on `swarm/<run>/host/<hid>/state`; the
host puts the commands its agents returned in one round of its loop as one `CmdBatch` on
`swarm/<run>/host/<hid>/cmd`. Every row carries its agent's id. Payloads are msgpack maps with packed little-endian
rows (one msgpack bin):

    state: v: 1, host: hid, k, t, n, rows: n x (id uint32, x, y, theta, px, py float64) (`STATE_ROW`, 44 bytes),
           scans: [[row, points, bodies], ...] (the rows with something in range, ascending; points and bodies as
           a state carries them: reconswarm/net/wire/wire.py)
    cmd:   v: 1, host: hid, n, rows: n x (id uint32, k int64, v_mps, omega_radps float64) (`CMD_ROW`, 28 bytes)

The sample's attachment is n, 4 bytes little-endian (what a host's inbox counts a state batch for; the payload's n
is what is believed). A host's states of one tick go out in more than one message only when their scans hold more
than `POINTS_PER_MESSAGE` points and bodies (each message well under the wire's size limit).

Decoding checks what a state or command's decoder checks of each row (finite numbers, ids and ticks in range,
points and bodies) and what a batch adds: the host field equals the key's, n rows exactly, no id twice (a command:
no id and tick twice), no id below the host's (its lowest), scan rows in range and ascending. Who a host may speak
for is the receiver's question (simworld/hosts.py, agent/robot_io.py).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import msgpack

from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import unpack_batch
from reconswarm.net.wire.keys import WireError
from reconswarm.scenario.wire_limits import MAX_AGENT_ID, MAX_ARRAY_LEN, MAX_STR_BYTES

STATE_ROW = struct.Struct("<Iddddd")  # id, x, y, theta, px, py
CMD_ROW = struct.Struct("<Iqdd")  # id, k, v_mps, omega_radps
MAX_TICK = 2**53
POINTS_PER_MESSAGE = 20_000  # scan points and bodies in one state message (~30 bytes each: under 1 MiB)


@dataclass(frozen=True)
class StateBatch:
    """The states of one host's agents at one tick, in one message (`host`: its key's `<hid>`)."""

    host: int
    states: tuple[wire.State, ...]


@dataclass(frozen=True)
class CmdBatch:
    """The commands one host's agents returned in one round of its loop, in one message."""

    host: int
    cmds: tuple[wire.Cmd, ...]


def attachment(n: int) -> bytes:
    return n.to_bytes(4, "little")


# ------------------------------------------------------------------------------------------- encode


def state_batches(host: int, states: list[wire.State]) -> list[tuple[bytes, int]]:
    """One tick's states of a host's agents as messages (payload, rows): one, unless their scans are too large."""
    out: list[tuple[bytes, int]] = []
    chunk: list[wire.State] = []
    points = 0
    for st in states:
        size = 0 if st.scan is None else len(st.scan.points) + len(st.scan.bodies)
        if chunk and points + size > POINTS_PER_MESSAGE:
            out.append((_states_to_wire(host, chunk), len(chunk)))
            chunk, points = [], 0
        chunk.append(st)
        points += size
    if chunk:
        out.append((_states_to_wire(host, chunk), len(chunk)))
    return out


def _states_to_wire(host: int, states: list[wire.State]) -> bytes:
    rows = b"".join(STATE_ROW.pack(s.id, s.x, s.y, s.theta, s.px, s.py) for s in states)
    scans = [[i, s.scan.points, s.scan.bodies] for i, s in enumerate(states) if s.scan is not None]
    first = states[0]
    return msgpack.packb({"v": wire.VERSION, "host": host, "k": first.k, "t": first.t, "n": len(states),
                          "rows": rows, "scans": scans}, use_bin_type=True)


def cmds_to_wire(host: int, cmds: list[wire.Cmd]) -> bytes:
    rows = b"".join(CMD_ROW.pack(c.id, c.k, c.v_mps, c.omega_radps) for c in cmds)
    return msgpack.packb({"v": wire.VERSION, "host": host, "n": len(cmds), "rows": rows}, use_bin_type=True)


# ------------------------------------------------------------------------------------------- decode


def _check_id(aid: int, host: int, seen: set[Any], once: Any) -> None:
    """aid in range for its host, and `once` (a state's id, a command's id and tick) not seen before in the batch."""
    if once in seen:
        raise WireError(f"field 'id': agent {aid} twice in one batch")
    if not host <= aid <= MAX_AGENT_ID:
        raise WireError(f"field 'id': agent {aid} below its host's lowest id {host} or out of range")
    seen.add(once)


def state_batch_from_wire(payload: bytes, key_host: int | None = None) -> StateBatch:
    """The states a payload carries; raises WireError for anything a state batch may not be."""
    o, host, n, raw = unpack_batch(payload, key_host, STATE_ROW, MAX_ARRAY_LEN, MAX_STR_BYTES)
    k, t = o.get("k"), o.get("t")
    if type(k) is not int or not 0 <= k <= MAX_TICK:
        raise WireError("field 'k': expected a tick")
    t = wire._num(t, "field 't'")
    scans: dict[int, wire.Scan] = {}
    raw_scans = o.get("scans", [])
    if type(raw_scans) is not list or len(raw_scans) > n:
        raise WireError(f"field 'scans': expected a list of at most {n} scans")
    ids = [r[0] for r in STATE_ROW.iter_unpack(raw)]
    for entry in raw_scans:
        if type(entry) is not list or len(entry) != 3 or type(entry[0]) is not int or not 0 <= entry[0] < n:
            raise WireError("field 'scans': each scan is [row, points, bodies]")
        i = entry[0]
        if scans and i <= max(scans):
            raise WireError("field 'scans': rows not ascending")
        scans[i] = wire.Scan(ids[i], k, t, wire._points({"points": entry[1]}), wire._bodies(entry[2]))
    out: list[wire.State] = []
    seen: set[Any] = set()
    for i, (aid, x, y, theta, px, py) in enumerate(STATE_ROW.iter_unpack(raw)):
        _check_id(aid, host, seen, aid)
        if not (x - x == 0.0 and y - y == 0.0 and theta - theta == 0.0 and px - px == 0.0 and py - py == 0.0):
            raise WireError(f"agent {aid}: a number not finite")
        out.append(wire.State(aid, k, t, x, y, theta, px, py, scans.get(i)))
    return StateBatch(host, tuple(out))


def cmd_batch_from_wire(payload: bytes, key_host: int | None = None) -> CmdBatch:
    """The commands a payload carries; raises WireError for anything a command batch may not be."""
    _o, host, _n, raw = unpack_batch(payload, key_host, CMD_ROW, MAX_ARRAY_LEN, MAX_STR_BYTES)
    out: list[wire.Cmd] = []
    seen: set[Any] = set()
    for aid, k, v, w in CMD_ROW.iter_unpack(raw):
        _check_id(aid, host, seen, (aid, k))
        if not 0 <= k <= MAX_TICK:
            raise WireError(f"field 'k' of agent {aid}: out of range")
        if not (v - v == 0.0 and w - w == 0.0):
            raise WireError(f"agent {aid}: a number not finite")
        out.append(wire.Cmd(aid, k, v, w))
    return CmdBatch(host, tuple(out))
