"""An agent host's inbox: the samples from zenoh with the subscription each came through (agent/host.py)."""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import zenoh

from reconswarm.net.runtime.inbox import Inbox, Item, to_item

ALL = ("all", None)  # the tag of a sample for every hosted agent (clock, liveliness)
# ALL | ("own", agent id) | ("cell", cell or None) | ("states", None): the subscription a sample came through
Tag = tuple[str, Any]


class TaggedInbox:
    """Samples from zenoh with the subscription they came through, in the order they came over the session's
    link (`handler`), held raw until the loop takes them all at once (inbox.Inbox's rules: `want` of them, or
    the hosted agents' states, wake the loop; nothing blocks or calls zenoh in a callback); counted in
    inbox.Inbox's process totals.

    The world publishes the states of a tick in one burst (in keys mode one message per host, counted for the
    states it carries; in ROS 2 mode one odometry per robot): the loop wakes once the states of all the hosted
    agents that wait for one are in (`urgent` of them), or `LINGER_S` after the first, so that one round, not
    several, takes the burst."""

    LINGER_S = 0.002  # how long the rest of a burst of states may take after its first
    MAX_ROWS = 4096  # the most a batch's attachment may count for

    def __init__(self) -> None:
        self._samples: deque[tuple[Tag, Any, float, int]] = deque()  # (tag, sample, at, states it counts for)
        self._ready = threading.Event()
        self._want: float = 1
        self._lock = threading.Lock()
        self._count = 0  # what the samples waiting count for: one each, a batch of beacons its rows (`rows`)

    def callback(self, tag: Tag, urgent: bool = False, rows: bool = False) -> Callable[[Any], None]:
        """rows: a host's batch counts for the rows it carries, as its attachment says (the nodes count the beacons
        they wait for; an urgent batch, our states, for the agents it has a state for); a wrong count only wakes
        the loop early, or at its poll."""
        def cb(sample: Any) -> None:
            n = 1
            if rows and (att := sample.attachment) is not None:
                n = min(self.MAX_ROWS, max(1, int.from_bytes(att.to_bytes()[:4], "little")))
            with self._lock:
                self._samples.append((tag, sample, time.monotonic(), (n if rows else 1) if urgent else 0))
                self._count += n
            if urgent or self._count >= self._want:
                self._ready.set()

        return cb

    def handler(self, tag: Tag, urgent: bool = False, rows: bool = False) -> Any:
        """A zenoh handler that appends to this inbox on the thread that received the sample (`indirect=False`):
        the samples of every subscription come in the order of the session's link. Lockstep needs that order:
        a peer's beacon of tick k-1 comes before the world's state of k (the world waits for the peer's command
        of k-1, put after that beacon), and the wait set of k is built from the beacons of k-1 in with the state
        (agent/neighbours.py). zenoh-python's default runs each subscription's callbacks on a Python thread of
        its own, and then a swamped cell subscription handed a beacon of k-1 over after the state of k."""
        return zenoh.handlers.Callback(self.callback(tag, urgent, rows), indirect=False)

    def _states(self) -> tuple[int, float]:
        """How many hosted agents' states wait (one per tag of a sample of one agent's, a batch's rows), and when the
        first came (inf: none)."""
        got = [(at, tag, n) for tag, _s, at, n in list(self._samples) if n]  # (list(): one atomic copy)
        alone = {tag for _at, tag, n in got if tag[0] == "own"}
        return len(alone) + sum(n for _at, tag, n in got if tag[0] != "own"), min((at for at, _t, _n in got),
                                                                                 default=math.inf)

    def take(self, want: int | None, timeout: float | None, urgent: int = 1) -> list[tuple[Tag, Item]]:
        """Every sample waiting, once `want` of them (None: only states) are in, or the states of `urgent` hosted
        agents (or some, `LINGER_S` ago), or once `timeout` seconds passed (at once if 0)."""
        self._want = math.inf if want is None else max(1, want)
        end = math.inf if timeout is None else time.monotonic() + timeout
        while timeout != 0:
            self._ready.clear()  # (before looking: a sample that comes after the look sets it again)
            if self._count >= self._want:
                break
            states, first = self._states()
            until = min(end, first + self.LINGER_S)
            now = time.monotonic()
            if states >= max(1, urgent) or now >= until:
                break
            self._ready.wait(None if until == math.inf else until - now)
        if timeout != 0:  # (a round that only hands over what co-hosted agents published does not count)
            Inbox.wakeups += 1
        out = []
        with self._lock:
            got, self._count = list(self._samples), 0
            self._samples.clear()
        for tag, sample, at, _n in got:
            item = to_item(sample, at)
            if item is not None:
                out.append((tag, item))
        Inbox.samples_in += len(out)
        return out
