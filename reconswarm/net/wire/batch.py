"""One message per agent host and cell: the beacons of the host's agents in that cell (docs/wire.md).

An agent host (`reconswarm agent --ids ...`, a lone agent included: a host of one) puts, once per round of its
runtime, one `BeaconBatch` per cell its agents' head points lie in, under
`swarm/<run>/cell/<cx>_<cy>/host/<hid>/beacons` (`hid`: the host's lowest agent id). The payload is a msgpack
map with the beacons as packed little-endian rows (`ROW`, 52 bytes each, one msgpack bin):

    v: 1, host: hid, n: rows, rows: n x (id uint32, k int64, t, px, py, radius float64, rev int64)

Decoding checks what `beacon_from_wire` checks of each row (finite numbers, radius > 0, ids and ticks in range)
and what a batch adds: the host field equals the key's, n rows exactly, no id twice, no id below the host's (its
lowest). A receiver admits each row by the rules of a beacon (reconswarm/net/trust/admission.py).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import msgpack

from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import WireError
from reconswarm.scenario.wire_limits import MAX_AGENT_ID, MAX_IDS, MAX_PAYLOAD_BYTES

# One row per beacon, packed little-endian: id uint32, k int64, t, px, py, radius float64, rev int64 (52 bytes; numpy's
# dtype [("id", "<u4"), ("k", "<i8"), ("t", "<f8"), ("px", "<f8"), ("py", "<f8"), ("radius", "<f8"), ("rev", "<i8")]).
FIELDS = ("id", "k", "t", "px", "py", "radius", "rev")
ROW = struct.Struct("<Iqddddq")
MAX_TICK = 2**53


@dataclass(frozen=True)
class BeaconBatch:
    """The beacons of one host's agents in one cell, in one message."""

    host: int  # the host's lowest agent id (its key's `<hid>`)
    beacons: tuple[wire.Beacon, ...]


def batch_to_wire(host: int, beacons: list[wire.Beacon] | tuple[wire.Beacon, ...]) -> bytes:
    rows = b"".join(ROW.pack(b.id, b.k, b.t, b.px, b.py, b.radius, b.rev) for b in beacons)
    return msgpack.packb({"v": wire.VERSION, "host": host, "n": len(beacons), "rows": rows}, use_bin_type=True)


def batch_from_wire(payload: bytes, key_host: int | None = None) -> BeaconBatch:
    """The batch a payload carries; raises WireError for anything a batch may not be."""
    _o, host, _n, raw = unpack_batch(payload, key_host, ROW)
    out: list[wire.Beacon] = []
    seen: set[int] = set()
    for aid, k, t, px, py, radius, rev in ROW.iter_unpack(raw):
        if aid in seen:
            raise WireError(f"field 'id': agent {aid} twice in one batch")
        if not host <= aid <= MAX_AGENT_ID:
            raise WireError(f"field 'id': agent {aid} below its host's lowest id {host} or out of range")
        if not (0 <= k <= MAX_TICK and 0 <= rev <= MAX_TICK):
            raise WireError(f"field 'k' or 'rev' of agent {aid}: out of range")
        if not (t - t == 0.0 and px - px == 0.0 and py - py == 0.0 and radius - radius == 0.0):  # (NaN, ±inf)
            raise WireError(f"agent {aid}: a number not finite")
        if not radius > 0:
            raise WireError(f"field 'radius' of agent {aid}: must be > 0")
        seen.add(aid)
        out.append(wire.Beacon(aid, k, t, px, py, radius, rev))
    return BeaconBatch(host, tuple(out))


def unpack_batch(payload: bytes, key_host: int | None, row: struct.Struct, max_array_len: int = 0,
                 max_str_len: int = 16) -> tuple[dict[str, Any], int, int, bytes]:
    """A host's batch (beacons, states, commands): its map, host, n and packed rows of `row`, checked as every batch
    is (size, version, the host its key names, 1..MAX_IDS rows); raises WireError."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise WireError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD_BYTES}")
    try:
        o = msgpack.unpackb(payload, raw=False, strict_map_key=True, max_array_len=max_array_len, max_map_len=8,
                            max_str_len=max_str_len, max_bin_len=row.size * MAX_IDS, max_ext_len=0)
    except Exception as exc:  # msgpack raises several unrelated exception types
        raise WireError(f"undecodable payload: {type(exc).__name__}") from None
    if not isinstance(o, dict):
        raise WireError("payload is not a map")
    if o.get("v") != wire.VERSION:
        raise WireError(f"schema version {o.get('v')!r}, expected {wire.VERSION}")
    host, n, raw = o.get("host"), o.get("n"), o.get("rows")
    if type(host) is not int or not 0 <= host <= MAX_AGENT_ID:
        raise WireError("field 'host': expected an agent id")
    if key_host is not None and host != key_host:
        raise WireError(f"field 'host': {host} under the key of host {key_host}")
    if type(n) is not int or not 0 < n <= MAX_IDS:
        raise WireError(f"field 'n': expected 1..{MAX_IDS} rows")
    if type(raw) is not bytes or len(raw) != n * row.size:
        raise WireError(f"field 'rows': expected {n} packed rows of {row.size} bytes")
    return o, host, n, raw
