"""Samples from zenoh handed to a process's own loop: the inbox (one for every role), who sent a sample, rejections.

Samples are handed from zenoh's callbacks to the process's loop through an `Inbox`: nothing blocks or calls
zenoh inside a callback; the loop takes them all at once (one wake-up per batch) and decodes them itself.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

log = logging.getLogger("reconswarm")


Item = tuple[str, bytes, str, str, float]  # key, payload, kind (PUT | DELETE), source (`sample_source`), arrival
Tag = Any  # the subscription a sample came through, as its process names it (None: a process that needs none)


class Inbox:
    """Samples from zenoh with the subscription each came through (its tag), held raw until the process's loop takes
    them all at once: one wake-up per batch. Nothing blocks or calls zenoh in a callback; the loop converts and
    decodes the batch itself.

    A take returns once `want` samples are in (a host's batch counts for the rows its attachment says, as the nodes
    count the messages they wait for), once the urgent samples of `urgent` nodes are in (an agent's state, which
    starts its tick; the world's states of a tick come in one burst: in keys mode one message per host, counted for
    the states it carries, in ROS 2 mode one odometry per robot), or `LINGER_S` after the first urgent one (so that
    one round, not several, takes the burst), or at its timeout.

    ordered: every subscription's callback runs on the thread that received the sample (`indirect=False`), so the
    samples of all subscriptions come in the order of the session's link (an agent host needs it: a peer's beacon
    of tick k-1 before the world's state of k, agent/neighbours.py). Otherwise zenoh-python runs each subscription's
    callbacks on a Python thread of its own, and zenoh's own threads never wait for the GIL (the world, the monitor:
    measured 2-4 % cheaper per agent at N = 36)."""

    samples_in = 0  # over every inbox of the process (for its exit line: benchmarks read them)
    wakeups = 0
    MAX_ROWS = 4096  # the most a batch's attachment may count for
    LINGER_S = 0.002  # how long the rest of a burst of urgent samples may take after its first

    def __init__(self, ordered: bool = False) -> None:
        self.ordered = ordered
        # (tag, sample, at, what it counts for among urgent ones, what it counts for, a batch with rows)
        self._samples: deque[tuple[Tag, Any, float, int, int, bool]] = deque()
        self._ready = threading.Event()
        self._want: float = 1
        self._lock = threading.Lock()
        self._count = 0  # what the samples waiting count for: one each, a batch its rows (`rows`)

    def callback(self, tag: Tag = None, urgent: bool = False, rows: bool = False) -> Callable[[Any], None]:
        """The function zenoh (or a ROS 2 subscription) calls with each sample of one subscription. urgent: its
        samples wake the loop (single samples count once per tag among urgent ones: one node's, its tag says
        whose; a batch, for its rows); rows: a host's batch counts for the rows its attachment says (4 bytes,
        little-endian, 1..MAX_ROWS; a wrong count only wakes the loop early, or at its poll: the payload's own
        count is what is believed)."""
        def cb(sample: Any) -> None:
            n = _rows(sample) if rows else 1
            with self._lock:
                self._samples.append((tag, sample, time.monotonic(), n if urgent else 0, n, rows))
                self._count += n
                ready = urgent or self._count >= self._want
            if ready:
                self._ready.set()

        return cb

    def handler(self, tag: Tag = None, urgent: bool = False, rows: bool = False) -> Any:
        """A zenoh handler feeding this inbox (see `callback`; on zenoh's receiving thread if `ordered`)."""
        import zenoh

        return zenoh.handlers.Callback(self.callback(tag, urgent, rows), indirect=not self.ordered)

    def _urgent(self) -> tuple[int, float]:
        """For how many nodes urgent samples wait (the tags of single samples, once each: two states of one agent
        are one; the rows of batches), and when the first came (inf: none)."""
        got = [(at, tag, n, batch) for tag, _s, at, n, _c, batch in list(self._samples) if n]  # (one atomic copy)
        alone = {tag for _at, tag, _n, batch in got if not batch}
        return len(alone) + sum(n for _at, _t, n, batch in got if batch), min((g[0] for g in got), default=math.inf)

    def take(self, want: int | None, timeout: float | None, urgent: int = 1) -> list[tuple[Tag, Item]]:
        """Every sample waiting with its tag, once `want` of them (None: only urgent ones) are in, or the urgent
        samples of `urgent` nodes (or some, `LINGER_S` ago), or once `timeout` seconds passed (at once if 0)."""
        self._want = math.inf if want is None else max(1, want)
        end = math.inf if timeout is None else time.monotonic() + timeout
        while timeout != 0:
            self._ready.clear()  # (before looking: a sample that comes after the look sets it again)
            if self._count >= self._want:
                break
            states, first = self._urgent()
            until = min(end, first + self.LINGER_S)
            now = time.monotonic()
            if states >= max(1, urgent) or now >= until:
                break
            self._ready.wait(None if until == math.inf else until - now)
        if timeout != 0:  # (a round that only hands over what co-hosted agents published does not count)
            Inbox.wakeups += 1
        with self._lock:
            got, self._count = list(self._samples), 0
            self._samples.clear()
        out = []
        for tag, sample, at, _u, _n, _b in got:
            item = to_item(sample, at)
            if item is not None:
                out.append((tag, item))
        Inbox.samples_in += len(out)
        return out


def _rows(sample: Any) -> int:
    """What a batch counts for: its attachment's row count, 1..MAX_ROWS (1 without a sane one)."""
    try:
        att = sample.attachment
        return 1 if att is None else min(Inbox.MAX_ROWS, max(1, int.from_bytes(att.to_bytes()[:4], "little")))
    except Exception:  # never raise into zenoh's callback
        return 1


def to_item(sample: Any, at_s: float) -> Item | None:
    """A zenoh sample that arrived at at_s (monotonic) as (key, payload bytes, PUT | DELETE, source, at_s)."""
    try:
        kind = "DELETE" if str(sample.kind).endswith("DELETE") else "PUT"
        return str(sample.key_expr), sample.payload.to_bytes(), kind, sample_source(sample), at_s
    except Exception as exc:  # a sample zenoh could not give us: dropped, and said
        log.error("inbox: cannot read a sample: %s", exc)
        return None


def sample_source(sample: Any) -> str:
    """Who published a sample: the id in its timestamp, which the publishing session stamps (every process
    of a run enables timestamping; a router stamps samples that arrive without one with its own id).
    "unattributed" if there is none. Any client can stamp a copied id: this attributes, it does not
    authenticate (see reconswarm/net/trust/admission.py)."""
    try:
        ts = sample.timestamp
        return str(ts.get_id()) if ts is not None else "unattributed"
    except Exception:  # never raise into zenoh's callback
        return "unattributed"


class Rejections:
    """Counts dropped messages and logs them at most once a second (with how many were suppressed)."""

    def __init__(self, who: str) -> None:
        self.who = who
        self.count = 0
        self._last_log = 0.0
        self._suppressed = 0

    def reject(self, key: str, reason: str) -> None:
        self.count += 1
        now = time.monotonic()
        if now - self._last_log >= 1.0:
            extra = f" (+{self._suppressed} more since the last report)" if self._suppressed else ""
            log.warning("%s: dropped a message on %s: %s%s [total %d]", self.who, key, reason, extra, self.count)
            self._last_log = now
            self._suppressed = 0
        else:
            self._suppressed += 1
