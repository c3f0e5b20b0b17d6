"""A host's beacons on the wire: one batch per cell and round out (net/wire/batch.py), each batch's rows admitted
one by one in (agent/host.py hands them to the agents listening to its cell).

Out: the beacons the hosted agents returned in a round of the runtime, grouped by the cell each was published from
(its home when it was returned), are put once the round is over (`flush`: before any command of the host goes out,
so a peer's beacon of tick k still precedes its command of k), one message per cell under
`cell/<cx>_<cy>/host/<hid>/beacons`, with its row count as its attachment (4 bytes, little-endian: what a receiving
host's inbox counts the sample for, as its nodes count the beacons they wait for). An agent returning two beacons in
one round (a re-announce and a new tick) goes out with the newer. A lone agent is a host of one; a re-announce alone
is a batch of one.

In: `take_batch` takes a peer host's decoded batch apart for the agents listening to its cell: each row judged by
the rules of a beacon, once for all of them (the host's one admission); a row in the name of an agent hosted here
is forged; a batch of more rows than the scenario has agents is malformed (counted by each agent it was for).

In the process: a co-hosted agent's beacon is handed to the others that listen to its cell as the message itself,
under a label that is no key of the run (`handover_label`: the wire has no per-agent beacon key).
"""

from __future__ import annotations

import time
from functools import lru_cache
from typing import Any

import zenoh

from agent.hosted import HostedAgent
from agent.messages import Input
from reconswarm.net.node import Invalid
from reconswarm.net.runtime import trace
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import BeaconBatch, batch_to_wire
from reconswarm.net.wire.cells import Cell, cell_chunk, chunk_cell
from reconswarm.net.wire.keys import Keys

HANDOVER = "handover"  # the head of a co-hosted beacon's label: outside `swarm/<run>/`, so no key of the run


def handover_label(cell: Cell, aid: int) -> str:
    """The label a co-hosted agent's beacon is handed over with in the process: `handover/<cx>_<cy>/<id>`, the cell
    it was returned in (whom it is for: the co-hosted agents listening to that cell). Not a key: beacons travel in
    host batches, and a put on a per-agent beacon key is an unexpected key (dropped and counted)."""
    return f"{HANDOVER}/{cell_chunk(cell)}/{aid}"


@lru_cache(maxsize=4096)
def handover_cell(label: str) -> Cell | None:
    """The cell a handover label names (None: not a label)."""
    head, _, rest = label.partition("/")
    if head != HANDOVER:
        return None
    return chunk_cell(rest.partition("/")[0])


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


def take_batch(m: BeaconBatch, key: str, source: str, who: list[int], batches: dict[int, list[Input]], at_s: float,
               active: dict[int, HostedAgent], gate: Gate, n_agents: int) -> None:
    """Hand a peer host's batch under `key` (from session `source`) to the hosted agents `who` listening to its
    cell, appending to their `batches`; `active`: the hosted agents' links, `gate`: the host's one admission,
    `n_agents`: the scenario's."""
    if len(m.beacons) > n_agents:
        bad = Invalid(key, f"a batch of {len(m.beacons)} beacons, the scenario has {n_agents} agents")
        for aid in who:
            if (got := active[aid].take(bad, key, source)) is not None:
                batches[aid].append(got)
        return
    now = time.monotonic()
    for b in m.beacons:
        if b.id in active:  # (rare: each agent's own link says what it is)
            for aid in who:
                link = active[aid]
                if aid != b.id:
                    link.refuse_cohosted(b.id, key, source)
                elif (mine := link.take(b, key, source)) is not None:
                    batches[aid].append(mine)
            continue
        refused = gate.check(b, source, key, now)
        if refused is not None:
            for aid in who:
                active[aid].gate.refuse(refused, now)
            continue
        for aid in who:
            batches[aid].append(b)
        trace.mark(trace.Mark.BEACON_IN, b.k, b.id, at_s)
