"""One message per agent host and cell: the beacons of the host's agents in that cell (docs/wire.md).

An agent host (`reconswarm agent --ids ...`, a lone agent included: a host of one) puts, once per round of its
runtime, one `BeaconBatch` per cell its agents' head points lie in, under
`swarm/<run>/cell/<cx>_<cy>/host/<hid>/beacons` (`hid`: the host's lowest agent id). The payload is a msgpack
map of packed little-endian columns, one row per beacon:

    v: 1, host: hid, n: rows,
    id: uint32[n], k: int64[n], t, px, py, radius: float64[n], rev: int64[n]   (each a msgpack bin)

Decoding checks what `beacon_from_wire` checks of each row (finite numbers, radius > 0, ids and ticks in range)
and what a batch adds: the host field equals the key's, every column has n rows, no id twice, no id below the
host's (its lowest). A receiver admits each row by the rules of a beacon (reconswarm/net/admission.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from reconswarm.net import wire
from reconswarm.net.keys import WireError
from reconswarm.scenario.wire_limits import MAX_AGENT_ID, MAX_IDS, MAX_PAYLOAD_BYTES

# The columns in their wire order, with their dtypes (little-endian).
COLUMNS: tuple[tuple[str, str], ...] = (("id", "<u4"), ("k", "<i8"), ("t", "<f8"), ("px", "<f8"), ("py", "<f8"),
                                        ("radius", "<f8"), ("rev", "<i8"))
_FLOATS = ("t", "px", "py", "radius")


@dataclass(frozen=True)
class BeaconBatch:
    """The beacons of one host's agents in one cell, in one message."""

    host: int  # the host's lowest agent id (its key's `<hid>`)
    beacons: tuple[wire.Beacon, ...]


def batch_to_wire(host: int, beacons: list[wire.Beacon] | tuple[wire.Beacon, ...]) -> bytes:
    cols: dict[str, Any] = {"v": wire.VERSION, "host": host, "n": len(beacons)}
    for name, dtype in COLUMNS:
        cols[name] = np.array([getattr(b, name) for b in beacons], dtype=dtype).tobytes()
    return msgpack.packb(cols, use_bin_type=True)


def batch_from_wire(payload: bytes, key_host: int | None = None) -> BeaconBatch:
    """The batch a payload carries; raises WireError for anything a batch may not be."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise WireError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD_BYTES}")
    try:
        o = msgpack.unpackb(payload, raw=False, strict_map_key=True, max_array_len=0, max_map_len=16,
                            max_str_len=16, max_bin_len=8 * MAX_IDS, max_ext_len=0)
    except Exception as exc:  # msgpack raises several unrelated exception types
        raise WireError(f"undecodable payload: {type(exc).__name__}") from None
    if not isinstance(o, dict):
        raise WireError("payload is not a map")
    if o.get("v") != wire.VERSION:
        raise WireError(f"schema version {o.get('v')!r}, expected {wire.VERSION}")
    host, n = o.get("host"), o.get("n")
    if type(host) is not int or not 0 <= host <= MAX_AGENT_ID:
        raise WireError("field 'host': expected an agent id")
    if key_host is not None and host != key_host:
        raise WireError(f"field 'host': {host} under the key of host {key_host}")
    if type(n) is not int or not 0 < n <= MAX_IDS:
        raise WireError(f"field 'n': expected 1..{MAX_IDS} rows")
    col: dict[str, np.ndarray] = {}
    for name, dtype in COLUMNS:
        raw = o.get(name)
        if type(raw) is not bytes or len(raw) != n * np.dtype(dtype).itemsize:
            raise WireError(f"field {name!r}: expected {n} packed {dtype} values")
        col[name] = np.frombuffer(raw, dtype=dtype)
    ids = col["id"]
    if int(ids.max()) > MAX_AGENT_ID:
        raise WireError("field 'id': out of range")
    if int(ids.min()) < host:
        raise WireError(f"field 'id': agent {int(ids.min())} below its host's lowest id {host}")
    if len(np.unique(ids)) != n:
        raise WireError("field 'id': an agent twice in one batch")
    for name in ("k", "rev"):
        if not ((col[name] >= 0) & (col[name] <= 2**53)).all():
            raise WireError(f"field {name!r}: out of range")
    for name in _FLOATS:
        if not np.isfinite(col[name]).all():
            raise WireError(f"field {name!r}: not finite")
    if not (col["radius"] > 0).all():
        raise WireError("field 'radius': must be > 0")
    rows = zip(*(col[name].tolist() for name, _ in COLUMNS), strict=True)
    return BeaconBatch(host, tuple(wire.Beacon(*row) for row in rows))
