"""`reconswarm flood`: publish malformed payloads on every key of a run (a fault-injection tool).

Every payload is invalid by construction, one of several kinds: random bytes, truncated msgpack, a wrong
schema version, NaN / inf numbers, wrong types, another agent's id, an oversized payload. A valid message
is never sent, so the run's outcome must not change; every receiver must drop and count each one it receives
(the run's router forwards no payload over the wire's limit: reconswarm/net/runtime/session.py PAYLOAD_CAP).
A host's keys are flooded under every agent's id (each a host id when it is a host's lowest or alone).
Beacons and obstacle sets go under the cell each agent is in when the flood starts (heard from the run's
beacons for up to 2 s; else the cell of its start), so the agents listening there receive them too.
Prints one JSON line: how many payloads went to each key (`sent`), how many of them were over the limit
(`over_limit`), and the total.
"""

from __future__ import annotations

import json
import math
import random
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack

from reconswarm.net.runtime.session import ZenohOptions, open_session
from reconswarm.net.wire.batch import batch_from_wire
from reconswarm.net.wire.cells import Cell, CellGrid, chunk_cell
from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.model import load
from reconswarm.scenario.wire_limits import MAX_PAYLOAD_BYTES


def _pack(o: Any) -> bytes:
    return msgpack.packb(o, use_bin_type=True)


def payloads(rng: random.Random, key_id: int) -> list[Callable[[], bytes]]:
    """Makers of malformed payloads for a key owned by agent key_id (or 0 for run-wide keys)."""
    other = key_id + 1
    return [
        lambda: rng.randbytes(rng.randint(0, 64)),
        lambda: _pack({"v": 1, "id": key_id, "k": 1, "t": 0.0, "px": 1.0})[:-3],  # truncated
        lambda: _pack({"v": 99, "id": key_id, "k": 1, "t": 0.0}),  # wrong schema version
        lambda: _pack({"v": 1, "id": key_id, "k": 1, "t": math.nan, "px": math.inf, "py": 0.0, "x": 0.0, "y": 0.0,
                       "theta": 0.0, "ux": math.nan, "uy": 0.0, "radius": math.inf, "alive": [], "ids": []}),
        lambda: _pack({"v": 1, "id": key_id, "k": "one", "t": "zero", "alive": "all", "points": 7, "obstacles": 3}),
        lambda: _pack({"v": 1, "id": other, "k": 1, "t": 0.0, "x": 0.0, "y": 0.0, "theta": 0.0, "px": 0.0,
                       "py": 0.0, "ux": 1.0, "uy": 1.0, "radius": 1.0, "rev": 1, "points": [], "obstacles": {}}),
        lambda: _pack([1, 2, 3]),
        lambda: b"\x00" * (MAX_PAYLOAD_BYTES + 1),  # over the size limit
    ]


@dataclass(frozen=True)
class FloodConfig:
    run: str
    scenario: Path | None
    count: int
    zenoh: ZenohOptions
    seed: int = 0


def _cells_now(session: Any, k: Keys, ids: list[int], start: dict[int, Cell]) -> dict[int, Cell]:
    """The cell of each agent's latest beacon (listening up to 2 s), else of its start."""
    heard: dict[int, Cell] = {}

    def got(sample: Any) -> None:
        key = str(sample.key_expr)
        try:  # (WireError is a ValueError)
            _, host, _ = k.parse(key)
            cell = chunk_cell(key.split("/")[-4])
            batch = batch_from_wire(sample.payload.to_bytes(), host)
        except ValueError:
            return
        for b in batch.beacons:
            heard[b.id] = cell

    sub = session.declare_subscriber(k.host_beacons(None, None), got)
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline and not set(ids) <= heard.keys():
        time.sleep(0.05)
    sub.undeclare()
    return {a: heard.get(a, start.get(a, (0, 0))) for a in ids}


def run(cfg: FloodConfig) -> dict[str, int]:
    s = load(cfg.scenario) if cfg.scenario else None
    ids = [a.id for a in s.agents] if s else list(range(1, 11))
    grid = CellGrid.for_scenario(s) if s else None
    start = {a.id: grid.cell_of(*a.start_m) for a in s.agents} if s and grid else {}
    k = Keys(cfg.run)
    rng = random.Random(cfg.seed)
    sent: dict[str, int] = {}
    over: dict[str, int] = {}
    import zenoh

    session = open_session(cfg.zenoh, "flood")
    try:
        cells = _cells_now(session, k, ids, start)
        keys: list[tuple[str, int]] = [(k.clock, 0), (k.truth, 0), (k.event, 0)]
        for a in ids:
            keys += [(k.host(a, "state"), a), (k.host(a, "cmd"), a), (k.host_beacons(cells[a], a), a),
                     (k.obstacles(cells[a], a), a)]
        pubs = {key: session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
                for key, _ in keys}
        makers = {key: payloads(rng, kid) for key, kid in keys}
        for n in range(cfg.count):
            key, _ = keys[n % len(keys)]
            maker = makers[key][rng.randrange(len(makers[key]))]
            payload = maker()
            pubs[key].put(payload)
            sent[key] = sent.get(key, 0) + 1
            if len(payload) > MAX_PAYLOAD_BYTES:
                over[key] = over.get(key, 0) + 1
    finally:
        session.close()
    print(json.dumps({"sent": sent, "over_limit": over, "total": cfg.count}), flush=True)
    return sent
