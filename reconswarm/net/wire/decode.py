"""One decode table: a sample's key and payload to the typed message a port takes, in one place.

`TABLE` maps a key's kind (`Kind`: the parsed key's kind and leaf; every report key is one kind) to its wire
decoder and the type it returns. Each port declares the kinds it accepts (`AGENT`, `WORLD`, `MONITOR`,
`LIVE_VIEW`) and calls `decode`: a kind it does not accept is None (not its), a key of none of the run's shapes
or a malformed payload raises the one `WireError` every port counts. What the port then does with the message
(its gate's admission, whom it is for) is the port's.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from reconswarm.net.node import Role, Token
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import BeaconBatch, batch_from_wire
from reconswarm.net.wire.hostwire import CmdBatch, StateBatch, cmd_batch_from_wire, state_batch_from_wire
from reconswarm.net.wire.keys import Keys, ParsedKey, WireError
from reconswarm.net.wire.report import Report, report_from_wire

Kind = tuple[str, str]  # (the key's kind, its leaf); a report key's leaf is ""
Message = (wire.State | wire.Scan | BeaconBatch | StateBatch | CmdBatch | wire.ObstacleSet | wire.Cmd | wire.Clock
           | wire.Truth | Report | Token)

SCAN: Kind = ("agent", "scan")
HOST_BEACONS: Kind = ("host", "beacons")
HOST_STATE: Kind = ("host", "state")
HOST_CMD: Kind = ("host", "cmd")
OBSTACLES: Kind = ("agent", "obstacles")
CLOCK: Kind = ("clock", "")
TRUTH: Kind = ("truth", "")
REPORT: Kind = ("report", "")
ALIVE_AGENT: Kind = ("alive", "agent")
ALIVE_HOST: Kind = ("alive", "host")
ALIVE_WORLD: Kind = ("alive", "simworld")
ALIVE_MONITOR: Kind = ("alive", "monitor")


class Entry(NamedTuple):
    """A kind's decoder (payload, parsed key, whether the sample is a PUT) and the type it returns."""

    decode: Callable[[bytes, ParsedKey, bool], Message]
    type: type


def _id(p: ParsedKey) -> int:
    assert p.agent_id is not None  # (an agent key's id: the parse raised for any other)
    return p.agent_id


TABLE: dict[Kind, Entry] = {
    SCAN: Entry(lambda b, p, _put: wire.scan_from_wire(b, _id(p)), wire.Scan),
    HOST_BEACONS: Entry(lambda b, p, _put: batch_from_wire(b, _id(p)), BeaconBatch),
    HOST_STATE: Entry(lambda b, p, _put: state_batch_from_wire(b, _id(p)), StateBatch),
    HOST_CMD: Entry(lambda b, p, _put: cmd_batch_from_wire(b, _id(p)), CmdBatch),
    OBSTACLES: Entry(lambda b, p, _put: wire.obstacles_from_wire(b, _id(p)), wire.ObstacleSet),
    CLOCK: Entry(lambda b, _p, _put: wire.clock_from_wire(b), wire.Clock),
    TRUTH: Entry(lambda b, _p, _put: wire.truth_from_wire(b), wire.Truth),
    REPORT: Entry(lambda b, p, _put: report_from_wire(b, p.leaf), Report),
    ALIVE_AGENT: Entry(lambda _b, p, put: Token(Role.AGENT, put, _id(p)), Token),
    ALIVE_HOST: Entry(lambda _b, p, put: Token(Role.HOST, put, _id(p), p.members or ()), Token),
    ALIVE_WORLD: Entry(lambda _b, _p, put: Token(Role.WORLD, put), Token),
    ALIVE_MONITOR: Entry(lambda _b, _p, put: Token(Role.MONITOR, put), Token),
}

# What each port accepts (the rest of the run's keys are not its). States and commands go in a host's batches
# (reconswarm/net/wire/hostwire.py).
AGENT = frozenset({HOST_STATE, SCAN, HOST_BEACONS, OBSTACLES, CLOCK, ALIVE_AGENT, ALIVE_WORLD})
WORLD = frozenset({HOST_CMD, ALIVE_AGENT, ALIVE_HOST, ALIVE_MONITOR})
MONITOR = frozenset({CLOCK, TRUTH, REPORT, ALIVE_AGENT, ALIVE_WORLD})
LIVE_VIEW = frozenset({OBSTACLES})  # the monitor's, while it serves the live view


def kind_of(p: ParsedKey) -> Kind:
    return (p.kind, "") if p.kind == "report" else (p.kind, p.leaf)


def decode(keys: Keys, accepts: frozenset[Kind], key: str, payload: bytes, sample_kind: str) -> Message | None:
    """The message a sample carries for a port that accepts `accepts` (None: a kind it does not); raises WireError
    for a key of none of the run's shapes or a malformed payload. sample_kind: zenoh's "PUT" or "DELETE" (a
    liveliness token's)."""
    p = keys.parsed(key)
    kind = kind_of(p)
    if kind not in accepts:
        return None
    return TABLE[kind].decode(payload, p, sample_kind != "DELETE")


__all__ = ["TABLE", "WireError", "decode", "kind_of"]
