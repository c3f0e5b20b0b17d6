"""The one decode table (reconswarm/net/wire/decode.py): each kind's decoder gives its type, a port takes only the kinds
it accepts, a cell key's cell comes from the key's one parse, and the live view's obstacle sets go through the
monitor's port: decoded by the same table, admitted (or refused and counted) by the monitor's gate."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import zenoh

from agent.beacons import handover_cell, handover_label
from monitor.process import MonitorAdapter
from reconswarm.net.node import Invalid, Role, Token
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.wire import decode as dec
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import batch_to_wire
from reconswarm.net.wire.hostwire import cmds_to_wire, state_batches
from reconswarm.net.wire.keys import Keys, ParsedKey, WireError
from reconswarm.net.wire.report import Report, report_to_wire
from reconswarm.record.store import RunWriter
from reconswarm.scenario.model import load
from tests.support import PAPER, free_port

K = Keys("t")
S = load(PAPER)
A = S.agents[0].id
SAMPLES: dict[dec.Kind, tuple[str, bytes]] = {  # a well-formed sample of each kind
    dec.HOST_STATE: (K.host(3, "state"), state_batches(3, [wire.State(3, 1, 0.05, 1.0, 2.0, 0.0, 1.0, 2.0)])[0][0]),
    dec.SCAN: (K.scan(3), wire.scan_to_wire(wire.Scan(3, 1, 0.05, ()))),
    dec.HOST_BEACONS: (K.host_beacons((1, -2), 3), batch_to_wire(3, [wire.Beacon(3, 1, 0.05, 1.0, 2.0, 0.5)])),
    dec.OBSTACLES: (K.obstacles((0, 0), 3), wire.obstacles_to_wire(wire.ObstacleSet(3, 1, 0))),
    dec.HOST_CMD: (K.host(3, "cmd"), cmds_to_wire(3, [wire.Cmd(3, 1, 0.5, 0.1)])),
    dec.CLOCK: (K.clock, wire.clock_to_wire(wire.Clock(1, 0.05, (3,)))),
    dec.TRUTH: (K.truth, wire.truth_to_wire(wire.Truth(1, 0.05, (3,), (1.0,), (2.0,), (0.0,), (1.0,), (2.0,)))),
    dec.REPORT: (K.report("agent-3"), report_to_wire(Report("agent-3", None, 2))),
    dec.ALIVE_AGENT: (K.alive_agent(3), b""),
    dec.ALIVE_HOST: (K.alive_host((3, 4)), b""),
    dec.ALIVE_WORLD: (K.alive_simworld, b""),
    dec.ALIVE_MONITOR: (K.alive_monitor, b""),
}
EVERY = frozenset(dec.TABLE)


def test_every_kind_decodes_to_its_type_and_a_port_takes_only_what_it_accepts() -> None:
    assert SAMPLES.keys() == dec.TABLE.keys()
    for kind, (key, payload) in SAMPLES.items():
        m = dec.decode(K, EVERY, key, payload, "PUT")
        assert isinstance(m, dec.TABLE[kind].type), (kind, m)
        for accepts in (dec.AGENT, dec.WORLD, dec.MONITOR, dec.LIVE_VIEW):
            got = dec.decode(K, accepts, key, payload, "PUT")
            assert (got is None) == (kind not in accepts), (kind, accepts)


def test_tokens_carry_their_role_id_and_whether_they_came_or_went() -> None:
    assert dec.decode(K, EVERY, K.alive_agent(4), b"", "DELETE") == Token(Role.AGENT, False, 4)
    assert dec.decode(K, EVERY, K.alive_simworld, b"", "PUT") == Token(Role.WORLD, True)
    assert dec.decode(K, EVERY, K.alive_monitor, b"", "DELETE") == Token(Role.MONITOR, False)


def test_a_bad_key_or_payload_raises_the_one_wire_error_whatever_the_port_accepts() -> None:
    for accepts, key, payload in ((frozenset(), "swarm/other/clock", b""),
                                  (frozenset(), K.prefix + "/agent/03/state", b""),
                                  (frozenset(), K.prefix + "/cell/01_0/agent/3/obstacles", b""),
                                  (dec.AGENT, K.host(3, "state"), b"\x00")):
        with pytest.raises(WireError):
            dec.decode(K, accepts, key, payload, "PUT")


def test_a_cell_key_gives_its_cell_from_the_one_parse() -> None:
    assert K.parsed(K.obstacles((-3, 4), 1)) == ParsedKey("agent", 1, "obstacles", (-3, 4))
    assert K.parsed(K.obstacles((0, 12), 2)).cell == (0, 12)
    assert K.parsed(K.host(2, "state")).cell is None and K.parsed(K.clock).cell is None
    assert K.parsed(K.host_beacons((-3, 4), 7)) == ParsedKey("host", 7, "beacons", (-3, 4))


def test_no_per_agent_beacon_key_a_put_on_one_is_unexpected() -> None:
    """Beacons travel in host batches: `cell/<c>/agent/<id>/beacon` is no key of the run, whatever port hears it."""
    key = K.in_cell((1, -2), 3, "beacon")
    with pytest.raises(WireError, match="unexpected key"):
        K.parsed(key)
    for accepts in (EVERY, dec.AGENT, dec.WORLD, dec.MONITOR, dec.LIVE_VIEW):
        with pytest.raises(WireError, match="unexpected key"):
            dec.decode(K, accepts, key, wire.beacon_to_wire(wire.Beacon(3, 1, 0.05, 1.0, 2.0, 0.5)), "PUT")


def test_a_co_hosted_beacons_label_names_its_cell_and_is_no_key() -> None:
    label = handover_label((-3, 4), 1)
    assert handover_cell(label) == (-3, 4) and handover_cell(K.obstacles((-3, 4), 1)) is None
    with pytest.raises(WireError):
        K.parsed(label)


@dataclass
class View:
    sets: list[wire.ObstacleSet] = field(default_factory=list)

    def obstacle_set(self, m: wire.ObstacleSet) -> None:
        self.sets.append(m)

    def close(self) -> None:
        pass


@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[MonitorAdapter, View]]:
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())  # alone
    writer = RunWriter(tmp_path / "run.db", S, "lockstep")
    port, view = MonitorAdapter(S, "t", z, writer, None), View()
    port.serve(view)  # type: ignore[arg-type]
    try:
        yield port, view
    finally:
        port.close()
        writer.close()
        z.close()


def test_the_live_views_sets_are_admitted_or_refused_and_counted_by_the_monitors_gate(
        served: tuple[MonitorAdapter, View]) -> None:
    port, view = served
    good = wire.ObstacleSet(A, 1, 0)
    unknown_agent = wire.ObstacleSet(9999, 1, 0)
    unknown_obstacle = wire.ObstacleSet(A, 1, 1, {"no-such": ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))})
    items = [(K.obstacles((0, 0), m.id), wire.obstacles_to_wire(m), "PUT", "s1", 0.0)
             for m in (good, unknown_agent, unknown_obstacle)]
    items.append((K.obstacles((0, 0), A), b"\x00garbage", "PUT", "s1", 0.0))
    got = port.route([(None, it) for it in items], 0.0)[0]
    assert view.sets == [good]  # (the view's, never the node's)
    assert port.gate.count == 2  # the unknown agent and the unknown obstacle: the monitor's intrusions
    assert len(got) == 1 and isinstance(got[0], Invalid) and port.rej.count == 1  # the malformed one
