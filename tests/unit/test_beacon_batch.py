"""One beacon message per host, cell and round (net/wire/batch.py, agent/beacons.py, agent/host.py): the codec
refuses what a batch may not be; a host puts its round's beacons as one message per cell, before any command of
the round; a receiving host judges each row as a beacon (each id pinned to the session it speaks from), counts a
batch larger than the scenario's swarm as malformed, and a row in a co-hosted agent's name as forged."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import msgpack
import pytest

from agent.host import AgentHost
from agent.neighbours import Cells
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import ROW, batch_from_wire, batch_to_wire
from reconswarm.net.wire.keys import WireError
from tests.support import wait_until
from tests.unit.test_agent_host_cases import OTHER, kinds, lone_host, route
from tests.unit.test_agent_host_routing import KEYS, PEER, at_start

A = (0, 0)


@pytest.fixture
def host() -> Iterator[AgentHost]:
    with lone_host() as h:  # (alone)
        yield h


def _b(aid: int, k: int = 3, px: float = 1.5, radius: float = 0.5) -> wire.Beacon:
    return wire.Beacon(aid, k, k * 0.05, px, -2.25, radius, 7)


def _raw(beacons: list[tuple[Any, ...]] | None = None, **over: Any) -> bytes:
    """A batch of host 3 with agents 3 and 4, or `beacons` (packed as ROW), with fields replaced by `over`."""
    rows = beacons if beacons is not None else [(3, 1, 0.05, 1.0, 2.0, 0.5, 0), (4, 1, 0.05, 2.0, 2.0, 0.5, 0)]
    o: dict[str, Any] = {"v": wire.VERSION, "host": 3, "n": len(rows), "rows": b"".join(ROW.pack(*r) for r in rows)}
    o.update(over)
    return msgpack.packb({k: v for k, v in o.items() if v is not None}, use_bin_type=True)


def _row(aid: int = 4, k: int = 1, t: float = 0.05, px: float = 1.0, radius: float = 0.5) -> tuple[Any, ...]:
    return (aid, k, t, px, 2.0, radius, 0)


def test_a_batch_round_trips_bit_for_bit() -> None:
    sent = (_b(3, px=0.1 + 0.2), _b(4, k=9, px=-1e-300), _b(10, px=123456.789))
    got = batch_from_wire(batch_to_wire(3, sent), 3)
    assert got.host == 3 and got.beacons == sent
    assert all(type(b.px) is float and type(b.k) is int for b in got.beacons)
    assert batch_from_wire(_raw(), 3).beacons[1] == wire.Beacon(4, 1, 0.05, 2.0, 2.0, 0.5, 0)


@pytest.mark.parametrize(("payload", "why"), [
    (_raw(host=4), "under the key of host 3"),
    (_raw(n=0), "field 'n'"),
    (_raw(n=3), "expected 3 packed rows"),
    (_raw(rows=None), "field 'rows'"),
    (_raw(rows=[1.0, 2.0]), "undecodable"),
    (_raw([_row(3), _row(3)]), "twice"),
    (_raw([_row(2), _row(4)]), "below its host's lowest id 3"),
    (_raw([_row(3), _row(2**31)]), "out of range"),
    (_raw([_row(3), _row(px=math.nan)]), "not finite"),
    (_raw([_row(3, t=math.inf)]), "not finite"),
    (_raw([_row(3), _row(radius=0.0)]), "radius"),
    (_raw([_row(3), _row(k=-1)]), "out of range"),
    (_raw(v=2), "schema version"),
    (b"\x05", "not a map"),
    (b"\xc1", "undecodable"),
    (b"\x00" * ((1 << 20) + 1), "exceeds"),
])
def test_a_malformed_batch_is_refused_with_its_reason(payload: bytes, why: str) -> None:
    with pytest.raises(WireError, match=why):
        batch_from_wire(payload, 3)


def _catch(host: AgentHost, *keys: str) -> list[tuple[str, bytes]]:
    got: list[tuple[str, bytes]] = []
    for key in keys:
        host.z.declare_subscriber(key, lambda s: got.append((str(s.key_expr), s.payload.to_bytes())))
    return got


def test_a_rounds_beacons_go_out_as_one_message_per_cell_once_the_round_is_over(host: AgentHost) -> None:
    got = _catch(host, KEYS.host_beacons(None, None))
    for aid in (1, 2):
        host.links[aid].cells(Cells(A, frozenset({A})))
    host.act(1, at_start(1), 0.0)
    host.act(2, at_start(2), 0.0)
    host.act(2, at_start(2, 1), 0.0)  # (a second one of agent 2 in the round: the newer goes)
    host.answers(0.0)  # (the round is over)
    wait_until(lambda: got, 10, "the round's batch")
    [(key, payload)] = got
    assert key == KEYS.host_beacons(A, 1)  # (under the host's lowest id)
    assert batch_from_wire(payload, 1).beacons == (at_start(1), at_start(2, 1))
    host.act(2, at_start(2, 1), 0.0)  # a re-announce alone: a batch of one
    host.answers(0.0)
    wait_until(lambda: len(got) == 2, 10, "the batch of one")
    assert batch_from_wire(got[1][1], 1).beacons == (at_start(2, 1),)


def test_a_beacon_goes_out_before_the_command_its_agent_returns_after_it(host: AgentHost) -> None:
    got = _catch(host, f"{KEYS.prefix}/**")  # (one subscription: what it hears, in the order put)
    host.act(1, at_start(1), 0.0)
    host.act(1, wire.Cmd(1, 0, 0.0, 0.0), 0.0)  # (a lone agent's: its law in its node, in the same round)
    host.act(1, at_start(1, 1), 0.0)  # (a beacon after the command in the round: put before the round's commands)
    assert host.answers(0.0) == {}  # the round is over: its commands go out, in one message

    def leaves() -> list[str]:
        return [leaf for key, _ in got if (leaf := key.rsplit("/", 1)[1]) in ("beacons", "cmd")]

    wait_until(lambda: len(leaves()) == 3, 10, "the beacons and the command")
    assert leaves() == ["beacons", "beacons", "cmd"]


def _sample(host_id: int, rows: list[wire.Beacon], source: str) -> tuple[str, bytes, str, str, float]:
    return KEYS.host_beacons(A, host_id), batch_to_wire(host_id, rows), "PUT", source, 0.0


def test_each_row_is_judged_as_a_beacon_of_the_session_it_speaks_from(host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(A, frozenset({A})))
    got = route(host, [(("cell", A), _sample(3, [at_start(3)], PEER))])  # pins agent 3 to PEER's session
    assert [(m.id, m.k) for m in got[1]] == [(3, 0)] and got[2] == got[1]
    # another session's batch naming agent 3 (and agent 4, heard first from it): agent 3's row is an intrusion,
    # counted once by each listening agent; agent 4's is believed
    got = route(host, [(("cell", A), _sample(3, [at_start(3, 1), at_start(4, 1)], OTHER))])
    assert [(m.id, m.k) for m in got[1]] == [(4, 1)] and [(m.id, m.k) for m in got[2]] == [(4, 1)]
    assert host.links[1].gate.count == 1 and host.links[2].gate.count == 1
    assert set(host.links[1].gate.tally.rows) == {("impersonation", OTHER)}


def test_a_row_in_a_co_hosted_agents_name_is_forged_and_a_batch_larger_than_the_swarm_malformed(
        host: AgentHost) -> None:
    host.listen(1, Cells(A, frozenset({A})))
    host.listen(2, Cells(A, frozenset({A})))
    got = route(host, [(("cell", A), _sample(1, [at_start(1), at_start(3)], PEER))])
    assert kinds(got[1]) == ["Invalid", "Beacon"] and kinds(got[2]) == ["Beacon"]  # (agent 3's row believed)
    assert host.links[1].rej.count == 1 and set(host.links[2].gate.tally.rows) == {("impersonation", PEER)}
    n = len(host.known) + 1
    big = _sample(20, [_b(20 + i) for i in range(n)], PEER)
    got = route(host, [(("cell", A), big)])
    assert kinds(got[1]) == kinds(got[2]) == ["Invalid"]
    assert host.links[2].rej.count == 1 and host.links[2].gate.count == 1  # (malformed: no intrusion)
