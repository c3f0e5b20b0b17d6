"""The floor benchmark (bench/floor.py, its pattern in bench/floor_pattern.py) mirrors the real protocol: the
beacons an agent waits for in the `cells` pattern are those a real agent's tick waits for on the grid
(agent/neighbours.py: its wait set plus the peers it hears anyway), and its payloads are the wire messages'
maps, byte for byte as long."""

from __future__ import annotations

import sys
from pathlib import Path

import msgpack
import pytest

from agent.neighbours import Neighbourhood
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import batch_from_wire

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import floor_pattern as floor
from grid import grid_scenario


@pytest.mark.parametrize("n", [16, 36, 64])
def test_cells_pattern_waits_for_what_a_real_agent_waits_for(n: int) -> None:
    s = grid_scenario(n, 10.0)
    pts = floor.head_points(s)
    ids = set(pts)
    for aid in sorted(ids):
        nb = Neighbourhood(s, aid)
        nb.on_state(0, pts[aid])
        nb.after_command(0)  # listening around p_i(0) from now on
        prev = {a: wire.Beacon(a, 0, 0.0, pts[a][0], pts[a][1], 1.5) for a in ids if a != aid}
        nb.on_state(1, pts[aid])  # robots still: the same point at tick 1
        waited = set(nb.wait_set(1, ids, prev, prev))
        also = nb.also_heard(ids, prev, {}, waited)
        hear, wait = floor.heard(s, aid, "cells")
        assert wait == waited
        assert wait <= hear and len(hear) == len(waited) + also
        all_hear, all_wait = floor.heard(s, aid, "all")
        assert all_hear == all_wait == ids - {aid}


def test_payloads_are_the_wire_maps() -> None:
    p = (12.345678901, -98.7654321)
    st = wire.state_from_wire(floor.state_bytes(7, 123, 6.15, p), 7)
    assert (st.k, st.px, st.py, st.scan) == (123, p[0], p[1], None)
    assert len(floor.state_bytes(7, 123, 6.15, p)) == len(wire.state_to_wire(st))
    b = wire.beacon_from_wire(floor.beacon_bytes(7, 123, 6.15, p, 1.5), 7)
    assert len(floor.beacon_bytes(7, 123, 6.15, p, 1.5)) == len(wire.beacon_to_wire(b))
    c = wire.cmd_from_wire(floor.cmd_bytes(7, 123), 7)
    assert len(floor.cmd_bytes(7, 123)) == len(wire.cmd_to_wire(c))
    alive = list(range(1, 65))
    clk = wire.clock_from_wire(floor.clock_bytes(123, 6.15, alive))
    assert clk.alive == tuple(alive) and not clk.end
    assert len(floor.clock_bytes(123, 6.15, alive)) == len(wire.clock_to_wire(clk))
    assert wire.clock_from_wire(floor.clock_bytes(124, 6.2, alive, end=True)).end


def test_the_batch_pattern_puts_the_wires_batch_and_counts_one_per_other_host_and_cell() -> None:
    rows = [(9, 123, 6.15, (1.25, -2.5), 1.5), (12, 123, 6.15, (3.0, 4.0), 0.5)]
    got = batch_from_wire(floor.batch_bytes(9, rows), 9)
    assert [(b.id, b.k, b.px, b.radius) for b in got.beacons] == [(9, 123, 1.25, 1.5), (12, 123, 3.0, 0.5)]
    assert floor.batch_rows(msgpack.unpackb(floor.batch_bytes(9, rows))) == [(9, 123), (12, 123)]
    s = grid_scenario(64, 10.0)
    for aid in (1, 30):
        peers = floor.heard(s, aid, "cells")[0]
        assert floor.sources(s, aid, 1) == len(peers)  # (a host of one: one batch per peer)
        assert floor.sources(s, aid, 64) == 0  # (every peer in our process: handed over in it)
        assert 0 < floor.sources(s, aid, 8) <= len(peers)
