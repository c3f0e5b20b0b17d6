"""One launch, one run: run ids and the endpoint lock (reconswarm_bringup/runid.py)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from reconswarm.errors import BadInput
from reconswarm.net.wire.keys import Keys
from reconswarm_bringup import runid


def test_run_ids_are_unique_valid_key_chunks(tmp_path: Path) -> None:
    drawn = [runid.new_run_id("paper") for _ in range(200)]
    ids = set(drawn)
    # 24 random bits: among 200 ids one pair collides with probability 0.12 % (seen once in CI), six pairs
    # practically never; a generator that repeats itself (a fixed seed, a counter reset) fails this.
    assert len(ids) >= 195
    for r in ids:
        assert re.fullmatch(r"paper-[0-9a-f]{6}", r)
        keys = Keys(r)
        assert keys.parse(keys.clock) == ("clock", None, "")
    runid.write_run_id(tmp_path, "paper-0a1b2c")
    assert (tmp_path / "run_id").read_text() == "paper-0a1b2c\n"
    assert runid.read_run_id(tmp_path) == "paper-0a1b2c"


def test_endpoint_lock_one_holder_at_a_time(tmp_path: Path) -> None:
    """flock locks belong to an open file: a second lock object stands for a second launch."""
    a = runid.EndpointLock("tcp/127.0.0.1:7600", tmp_path)
    a.acquire("paper-aaaaaa")
    try:
        for ep in ("tcp/127.0.0.1:7600", "tls/127.0.0.1:7600"):  # the same port, whatever the protocol
            with pytest.raises(BadInput, match=f"{ep}: router in use by run paper-aaaaaa"):
                runid.EndpointLock(ep, tmp_path).acquire("paper-bbbbbb")
        other = runid.EndpointLock("tcp/127.0.0.1:7601", tmp_path)
        other.acquire("paper-bbbbbb")  # another port is free
        other.release()
    finally:
        a.release()
    b = runid.EndpointLock("tcp/127.0.0.1:7600", tmp_path)
    b.acquire("paper-cccccc")  # released: the next launch gets it
    b.release()
