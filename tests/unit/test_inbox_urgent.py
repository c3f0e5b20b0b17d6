"""The inbox of an agent host (reconswarm/net/runtime/inbox.py, `ordered`, tagged samples) against its rules, fed
by hand as zenoh's callbacks feed it: the loop wakes once `want` samples are in, or once the states (urgent samples)
of `urgent` hosted agents are in, so that one round takes the world's burst of states, or `LINGER_S` after the first
state if the rest does not come.

Also: one sample wanted, or one agent's state, wakes a take; with nothing, a take waits its timeout out, counts its
wakeup and the samples it took, and stamps each with when it arrived.

(Each take runs in a thread joined with a long timeout: a take that waits when it should not hangs there.)"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

from reconswarm.net.runtime.inbox import Inbox


class Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class Sample:
    """What the inbox reads of a zenoh sample (inbox.to_item)."""

    def __init__(self, key: str, attachment: bytes | None = None) -> None:
        self.key_expr, self.payload, self.kind, self.timestamp = key, Payload(b"x"), "PUT", None
        self.attachment = None if attachment is None else Payload(attachment)


def fill(inbox: Inbox, *who: int | str) -> None:
    """An agent's state (urgent) for each int, a beacon for each string."""
    for w in who:
        if isinstance(w, int):
            inbox.callback(("own", w), urgent=True)(Sample(f"s/agent/{w}/state"))
        else:
            inbox.callback(("cell", None))(Sample(w))


def take(inbox: Inbox, want: int | None, urgent: int, later: list[int | str] | None = None,
         timeout: float | None = None) -> list[str]:
    """The keys one take returns (None: it did not return); `later` is fed 0.2 s after the take started."""
    got: list[Any] = []
    t = threading.Thread(target=lambda: got.extend(inbox.take(want, timeout, urgent)))
    t.start()
    if later:
        time.sleep(0.2)
        fill(inbox, *later)
    t.join(30.0)
    assert not t.is_alive(), "the take is still waiting"
    return [item[0] for _tag, item in got]


def test_the_states_of_every_hosted_agent_waiting_for_one_wake_the_loop_together() -> None:
    inbox = Inbox(ordered=True)
    inbox.LINGER_S = math.inf  # (the rest of the burst is waited for as long as it takes)
    fill(inbox, 1, 2)
    assert take(inbox, None, 3, later=[3]) == ["s/agent/1/state", "s/agent/2/state", "s/agent/3/state"]


def test_two_states_of_one_agent_count_once() -> None:
    inbox = Inbox(ordered=True)
    inbox.LINGER_S = math.inf
    fill(inbox, 1, 1)
    assert len(take(inbox, None, 2, later=[2])) == 3


def test_the_rest_of_a_burst_is_not_waited_for_past_the_linger() -> None:
    inbox = Inbox(ordered=True)
    inbox.LINGER_S = 0.0
    fill(inbox, 1)
    assert take(inbox, None, 3) == ["s/agent/1/state"]


def test_want_samples_wake_the_loop_whatever_states_are_missing() -> None:
    inbox = Inbox(ordered=True)
    fill(inbox, "b/1", "b/2")
    assert take(inbox, 3, 5, later=["b/3"]) == ["b/1", "b/2", "b/3"]


def test_a_timeout_of_zero_takes_what_is_there_at_once() -> None:
    inbox = Inbox(ordered=True)
    inbox.LINGER_S = math.inf
    fill(inbox, 1, "b/1")
    assert take(inbox, 5, 3, timeout=0.0) == ["s/agent/1/state", "b/1"]
    assert take(inbox, 5, 3, timeout=0.0) == []


def test_a_take_waits_for_its_timeout_and_counts_its_wakeup_and_samples() -> None:
    inbox = Inbox(ordered=True)
    wakeups, samples = Inbox.wakeups, Inbox.samples_in
    assert timed_take(inbox, 1, 1.0, 1) == [] and Inbox.wakeups == wakeups + 1 and Inbox.samples_in == samples
    t0 = time.monotonic()
    inbox.callback(("cell", None))(Sample("b/1"))
    inbox.callback(("cell", None))(Sample("b/2"))
    got = inbox.take(5, 0.0)
    assert [it[0] for _t, it in got] == ["b/1", "b/2"] and all(t0 <= it[4] <= time.monotonic() for _t, it in got)
    assert Inbox.wakeups == wakeups + 1 and Inbox.samples_in == samples + 2  # (a take at once: no wakeup)


def test_one_sample_wanted_or_one_agents_state_wakes_the_take() -> None:
    inbox = Inbox(ordered=True)
    inbox.LINGER_S = 60.0
    threading.Timer(0.2, lambda: inbox.callback(("cell", None))(Sample("b/1"))).start()
    assert [it[0] for _t, it in timed_take(inbox, 1, 30.0, 5, at_most_s=15.0)] == ["b/1"]
    threading.Timer(0.2, lambda: inbox.callback(("own", 1), urgent=True)(Sample("s/1"))).start()
    assert [it[0] for _t, it in timed_take(inbox, None, 30.0, 1, at_most_s=15.0)] == ["s/1"]


def timed_take(inbox: Inbox, want: int | None, timeout: float, urgent: int,
               at_most_s: float = 60.0) -> list[Any]:
    """One take in a thread: it returns after its timeout at the earliest when nothing wakes it (then the
    result is []), within at_most_s when something does."""
    got: list[Any] = []
    t0 = time.monotonic()
    taker = threading.Thread(target=lambda: got.extend(inbox.take(want, timeout, urgent)))
    taker.start()
    taker.join(at_most_s + timeout)
    took = time.monotonic() - t0
    assert not taker.is_alive() and took < at_most_s, f"the take took {took:.1f} s"
    if not got:
        assert took >= 0.9 * timeout, f"nothing came, yet the take returned after {took:.2f} s of {timeout} s"
    return got


def test_a_batch_of_beacons_counts_for_its_rows_as_its_attachment_says() -> None:
    """The nodes count the beacons they wait for; a host's batch carries several (agent/beacons.py)."""
    inbox = Inbox(ordered=True)
    inbox.callback(("cell", None), rows=True)(Sample("s/cell/0_0/host/1/beacons", (3).to_bytes(4, "little")))
    t0 = time.monotonic()
    assert take(inbox, 3, 1, timeout=30.0) == ["s/cell/0_0/host/1/beacons"]  # (3 wanted: in at once)
    assert time.monotonic() - t0 < 10.0
    for att in (None, b"", (0).to_bytes(4, "little")):  # (none, or a forged count: one sample, no more)
        inbox.callback(("cell", None), rows=True)(Sample("s/cell/0_0/host/1/beacons", att))
        t0 = time.monotonic()
        assert take(inbox, 2, 1, timeout=0.3) == ["s/cell/0_0/host/1/beacons"]
        assert time.monotonic() - t0 >= 0.25  # (one of the 2 wanted: the take waited its timeout out)
