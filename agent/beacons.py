"""A host's beacons on the wire: one batch per cell and round out (reconswarm/net/batch.py), each batch's rows admitted
one by one in (agent/host.py hands them to the agents listening to its cell).

Out: the beacons the hosted agents returned in a round of the runtime, grouped by the cell each was published from
(its home when it was returned), are put once the round is over (`flush`: before any command of the host goes out,
so a peer's beacon of tick k still precedes its command of k), one message per cell under
`cell/<cx>_<cy>/host/<hid>/beacons`, with its row count as its attachment (4 bytes, little-endian: what a receiving
host's inbox counts the sample for, as its nodes count the beacons they wait for). An agent returning two beacons in
one round (a re-announce and a new tick) goes out with the newer. A lone agent is a host of one; a re-announce alone
is a batch of one.

In: `rows` takes a decoded batch apart, bounded by the scenario's agent count (a larger one is malformed).
"""

from __future__ import annotations

from typing import Any

import zenoh

from reconswarm.net import trace, wire
from reconswarm.net.batch import BeaconBatch, batch_to_wire
from reconswarm.net.cells import Cell
from reconswarm.net.keys import Keys, WireError


class BeaconOut:
    """The beacons of one round, by cell, and a publisher per cell the host publishes from."""

    def __init__(self, session: zenoh.Session, keys: Keys, hid: int) -> None:
        self.z, self.keys, self.hid = session, keys, hid
        self.pending: dict[Cell, dict[int, wire.Beacon]] = {}  # cell -> agent -> its newest beacon of the round
        self.pubs: dict[Cell, Any] = {}  # cell -> publisher (declared at its first batch)

    def add(self, cell: Cell, b: wire.Beacon) -> None:
        held = self.pending.setdefault(cell, {})
        had = held.get(b.id)
        if had is None or had.k <= b.k:
            held[b.id] = b

    def flush(self, homes: set[Cell]) -> None:
        """Put what the round returned, one batch per cell; `homes`: the cells the hosted agents publish from now
        (a publisher of any other cell goes)."""
        if not self.pending:
            return
        pending, self.pending = self.pending, {}
        for cell, held in pending.items():
            pub = self.pubs.get(cell)
            if pub is None:
                pub = self.pubs[cell] = self.z.declare_publisher(self.keys.host_beacons(cell, self.hid),
                                                                 congestion_control=zenoh.CongestionControl.BLOCK)
            beacons = sorted(held.values(), key=lambda b: b.id)
            pub.put(batch_to_wire(self.hid, beacons), attachment=len(beacons).to_bytes(4, "little"))
            for b in beacons:
                trace.mark(trace.Mark.BEACON_PUT, b.k, b.id)
        for cell in [c for c in self.pubs if c not in homes and c not in pending]:
            self.pubs.pop(cell).undeclare()

    def close(self) -> None:
        for pub in self.pubs.values():
            pub.undeclare()
        self.pubs.clear()


def rows(batch: BeaconBatch, n_agents: int) -> tuple[wire.Beacon, ...]:
    """A batch's beacons; raises WireError for one with more rows than the scenario has agents."""
    if len(batch.beacons) > n_agents:
        raise WireError(f"a batch of {len(batch.beacons)} beacons, the scenario has {n_agents} agents")
    return batch.beacons
