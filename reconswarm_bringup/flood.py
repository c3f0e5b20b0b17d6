"""`reconswarm flood`: publish malformed payloads on every key of a run (a fault-injection tool).

Every payload is invalid by construction, one of several kinds: random bytes, truncated msgpack, a wrong
schema version, NaN / inf numbers, wrong types, another agent's id, an oversized payload. A valid message
is never sent, so the run's outcome must not change; every receiver must drop and count each one.
Prints one JSON line: how many payloads went to each key.
"""

from __future__ import annotations

import json
import math
import random
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack

from reconswarm.net import wire
from reconswarm.net.session import ZenohOptions, open_session
from reconswarm.scenario import load


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
        lambda: b"\x00" * (wire.MAX_PAYLOAD_BYTES + 1),  # over the size limit
    ]


@dataclass(frozen=True)
class FloodConfig:
    run: str
    scenario: Path | None
    count: int
    zenoh: ZenohOptions
    seed: int = 0


def run(cfg: FloodConfig) -> dict[str, int]:
    ids = [a.id for a in load(cfg.scenario).agents] if cfg.scenario else list(range(1, 11))
    k = wire.Keys(cfg.run)
    keys: list[tuple[str, int]] = [(k.clock, 0), (k.truth, 0), (k.event, 0)]
    for a in ids:
        keys += [(k.state(a), a), (k.scan(a), a), (k.cmd(a), a), (k.beacon(a), a), (k.obstacles(a), a)]
    rng = random.Random(cfg.seed)
    sent: dict[str, int] = {}
    import zenoh

    session = open_session(cfg.zenoh, "flood")
    try:
        pubs = {key: session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
                for key, _ in keys}
        makers = {key: payloads(rng, kid) for key, kid in keys}
        for n in range(cfg.count):
            key, _ = keys[n % len(keys)]
            maker = makers[key][rng.randrange(len(makers[key]))]
            pubs[key].put(maker())
            sent[key] = sent.get(key, 0) + 1
    finally:
        session.close()
    print(json.dumps({"sent": sent, "total": cfg.count}), flush=True)
    return sent
