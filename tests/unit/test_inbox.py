"""The inbox (reconswarm/net/runtime/inbox.py) that hands zenoh's samples to a process's loop in batches: who wakes
the loop and when, for a process with one node (the world, the monitor: untagged samples; an agent host's rules:
test_inbox_urgent.py). Driven by hand with sample-shaped objects (the zenoh side is exercised by tests/system)."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

from reconswarm.net.runtime.inbox import Inbox, Item


@dataclass
class Payload:
    data: bytes

    def to_bytes(self) -> bytes:
        return self.data


@dataclass
class Sample:
    key_expr: str
    payload: Payload
    kind: str = "SampleKind.PUT"
    timestamp: None = None


def sample(i: int, kind: str = "SampleKind.PUT") -> Sample:
    return Sample(f"swarm/r/agent/{i}/beacon", Payload(bytes([i])), kind)


def items(got: list[tuple[Any, Item]]) -> list[Item]:
    """What an untagged inbox took: every sample's tag is None."""
    assert all(tag is None for tag, _it in got)
    return [it for _tag, it in got]


def put_three(box: Inbox) -> None:
    for i in range(3):
        box.callback()(sample(i))


def test_the_loop_sleeps_until_the_count_it_waits_for_is_in() -> None:
    box = Inbox()
    for i in range(2):
        box.callback()(sample(i))
    t0 = time.monotonic()
    got = items(box.take(3, 0.2))
    want = [(f"swarm/r/agent/{i}/beacon", bytes([i]), "PUT", "unattributed") for i in range(2)]
    assert [it[:4] for it in got] == want
    assert t0 - 1.0 < got[0][4] <= got[1][4] <= t0  # when each arrived, not when the loop took it
    assert time.monotonic() - t0 >= 0.19  # two of three: it waited for its timeout
    threading.Timer(0.05, put_three, args=(box,)).start()
    t0 = time.monotonic()
    assert len(box.take(3, 5.0)) == 3
    assert time.monotonic() - t0 < 4.0  # woken by the third sample, not by the timeout


def test_an_urgent_sample_wakes_the_loop_at_once_with_everything_waiting() -> None:
    box = Inbox()
    box.callback()(sample(1))
    threading.Timer(0.05, box.callback(urgent=True), args=(sample(2),)).start()
    t0 = time.monotonic()
    got = items(box.take(None, 5.0))  # None: only an urgent sample (or the timeout) wakes it
    assert [key for key, *_ in got] == ["swarm/r/agent/1/beacon", "swarm/r/agent/2/beacon"]
    assert time.monotonic() - t0 < 4.0


def test_a_deleted_sample_and_an_unreadable_one() -> None:
    box = Inbox()
    box.callback()(sample(7, "SampleKind.DELETE"))
    box.callback()(Sample("k", None))  # type: ignore[arg-type]  # no payload: dropped (logged), the rest is kept
    box.callback()(sample(8))
    got = items(box.take(1, 0))
    assert [(key[-8:], kind) for key, _, kind, _, _ in got] == [("7/beacon", "DELETE"), ("8/beacon", "PUT")]
    assert box.take(1, 0) == []


@dataclass
class Batch(Sample):
    attachment: Payload | None = None


def host_commands(host: int, rows: int) -> Batch:
    return Batch(f"swarm/r/host/{host}/cmd", Payload(bytes([host])), attachment=Payload(rows.to_bytes(4, "little")))


def test_a_hosts_batch_counts_for_its_rows_so_the_world_is_woken_by_the_last_hosts_commands() -> None:
    """The world waits for ten commands; two hosts of five answer in one message each (their attachments say 5):
    the second wakes it, not its poll (before: each batch counted one, and every lockstep tick took the poll)."""
    box = Inbox()
    box.callback(rows=True)(host_commands(1, 5))
    threading.Timer(0.05, box.callback(rows=True), args=(host_commands(6, 5),)).start()
    t0 = time.monotonic()
    got = items(box.take(10, 5.0))
    assert [key for key, *_ in got] == ["swarm/r/host/1/cmd", "swarm/r/host/6/cmd"]
    assert time.monotonic() - t0 < 4.0
    # Nothing is left counted once taken: the next take waits again for what it wants.
    box.callback(rows=True)(host_commands(1, 5))
    t0 = time.monotonic()
    assert len(box.take(10, 0.2)) == 1 and time.monotonic() - t0 >= 0.19


def test_a_batch_without_a_sane_attachment_counts_one_and_never_more_than_the_cap() -> None:
    box = Inbox()
    box.callback(rows=True)(Batch("swarm/r/host/1/cmd", Payload(b"x")))  # no attachment: one
    box.callback(rows=True)(Batch("swarm/r/host/2/cmd", Payload(b"x"), attachment=Payload(b"")))  # empty: one
    t0 = time.monotonic()
    assert len(box.take(3, 0.2)) == 2 and time.monotonic() - t0 >= 0.19  # two counted: it waited
    box.callback(rows=True)(host_commands(3, 2**31))  # a forged count: capped, it only wakes the loop early
    assert box._count == Inbox.MAX_ROWS
    assert len(box.take(10, 5.0)) == 1 and box._count == 0
