"""The zenoh side shared by every process: options, session, signals, inbox and rejection counting.

Every process takes the same options (`--connect EP`, `--listen EP`, `--mode peer|client|router`,
`--zenoh-config FILE.json5`); multicast scouting is off unless a config file turns it on; clients wait
for their router (and reconnect by themselves when it restarts). Samples are handed from zenoh's
callbacks to the process's own loop through an `Inbox`: nothing blocks or calls zenoh inside a callback.
"""

from __future__ import annotations

import json
import logging
import math
import signal
import threading
import time
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from reconswarm.errors import BadInput, ProcessFailure
from reconswarm.net.timing import TIMING

log = logging.getLogger("reconswarm")
MODES = ("peer", "client", "router")
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
LEASE_MS = TIMING.lease_ms  # a frozen process is declared gone after this (zenoh's 10 s is too slow for robots)


@dataclass(frozen=True)
class ZenohOptions:
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    mode: str = "client"
    config_file: Path | None = None

    @staticmethod
    def build(connect: list[str] | None, listen: list[str] | None, mode: str,
              config_file: Path | None) -> ZenohOptions:
        if mode not in MODES:
            raise BadInput(f"--mode: expected one of {', '.join(MODES)}, got {mode!r}")
        for ep in [*(connect or []), *(listen or [])]:
            if "/" not in ep:
                raise BadInput(f"--connect/--listen: endpoint {ep!r} is not of the form proto/address (tcp/host:port)")
        if config_file is not None and not config_file.is_file():
            raise BadInput(f"{config_file}: zenoh config file not found")
        if config_file is None and mode == "client" and not connect:
            connect = [DEFAULT_ROUTER]
        return ZenohOptions(tuple(connect or ()), tuple(listen or ()), mode, config_file)

    def config(self) -> Any:
        import zenoh

        if self.config_file is not None:
            try:
                conf = zenoh.Config.from_file(str(self.config_file))
            except Exception as exc:
                raise BadInput(f"{self.config_file}: invalid zenoh config: {exc}") from None
        else:
            conf = zenoh.Config()
            conf.insert_json5("mode", json.dumps(self.mode))
            conf.insert_json5("scouting/multicast/enabled", "false")
            conf.insert_json5("transport/link/tx/lease", str(LEASE_MS))
            conf.insert_json5("connect/timeout_ms", '{"router": -1, "peer": -1, "client": 15000}')
        # Advanced publishers (late joiners' obstacle sets) need timestamps.
        conf.insert_json5("timestamping/enabled", "true")
        if self.connect:
            conf.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        if self.listen:
            conf.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        return conf


@contextmanager
def serving(opts: ZenohOptions, what: str,
            timeout_s: float = TIMING.session_open_timeout_s) -> Iterator[tuple[Any, Stopper]]:
    """A process's session and its SIGINT/SIGTERM flag; the session is closed however the body ends."""
    stop = Stopper()
    session = open_session(opts, what, timeout_s)
    try:
        yield session, stop
    finally:
        session.close()
        log.info("usage: %s", usage())


class Member:
    """A process that announces itself with a liveliness token (closing withdraws it)."""

    token: Any

    def close(self) -> None:
        with suppress(Exception):
            self.token.undeclare()


def open_session(opts: ZenohOptions, what: str, timeout_s: float = TIMING.session_open_timeout_s) -> Any:
    """Open a session, retrying until the router answers or the timeout passes (then ProcessFailure)."""
    import zenoh

    deadline = time.monotonic() + timeout_s
    last: Exception | None = None
    while time.monotonic() < deadline:
        try:
            return zenoh.open(opts.config())
        except BadInput:
            raise
        except Exception as exc:  # zenoh.ZError: router not up yet, port in use, ...
            last = exc
            time.sleep(0.2)
    raise ProcessFailure(f"{what}: cannot open a zenoh session ({', '.join(opts.connect or opts.listen)}): {last}")


class Stopper:
    """SIGINT / SIGTERM set a flag the main loop polls; the session is closed in the loop's finally."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal: int | None = None
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)

    def _handle(self, signum: int, _frame: Any) -> None:
        self.signal = signum
        self.event.set()

    @property
    def stopped(self) -> bool:
        return self.event.is_set()


Item = tuple[str, bytes, str, str, float]  # key, payload, kind (PUT | DELETE), source (`sample_source`), arrival


class Inbox:
    """Samples from zenoh, held raw until the main loop takes them all at once: one wake-up per batch.

    `handler()` gives zenoh a callback (run by zenoh-python in a Python thread of the subscriber's, so zenoh's
    own threads never wait for the GIL: measured 2-4 % cheaper per agent than running it on zenoh's receiving
    thread, `indirect=False`, at N = 36); it only appends the sample with its arrival time and, for an urgent
    subscriber (the tick's trigger) or once `want` samples wait, wakes the loop. The loop converts and
    decodes the batch itself. Nothing blocks or calls zenoh in the callback."""

    samples_in = 0  # over every inbox of the process (for its exit line: benchmarks read them)
    wakeups = 0

    def __init__(self) -> None:
        self._samples: deque[tuple[Any, float]] = deque()  # (sample, monotonic time it arrived)
        self._ready = threading.Event()
        self._want: float = 1
        self._urgent = False  # an urgent sample came since the last take

    def handler(self, urgent: bool = False) -> Any:
        """A zenoh handler that feeds this inbox (urgent: each sample wakes the loop at once)."""
        import zenoh

        return zenoh.handlers.Callback(self.urgent if urgent else self.callback)

    def callback(self, sample: Any) -> None:
        self._samples.append((sample, time.monotonic()))
        if len(self._samples) >= self._want:
            self._ready.set()

    def urgent(self, sample: Any) -> None:
        self._samples.append((sample, time.monotonic()))
        self._urgent = True
        self._ready.set()

    def take(self, want: int | None, timeout: float | None) -> list[Item]:
        """Every sample waiting, once an urgent one or `want` of them (None: only an urgent one) are in, or
        once `timeout` seconds passed (at once if 0)."""
        self._want = math.inf if want is None else max(1, want)
        self._ready.clear()  # (set by samples an earlier take already had, or that were fewer than wanted then)
        if not self._urgent and len(self._samples) < self._want and (timeout is None or timeout > 0):
            self._ready.wait(timeout)
        self._urgent = False
        Inbox.wakeups += 1
        return self.drain()

    def drain(self) -> list[Item]:
        """Every sample waiting, without waiting."""
        out = []
        while self._samples:
            item = to_item(*self._samples.popleft())
            if item is not None:
                out.append(item)
        Inbox.samples_in += len(out)
        return out


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
    authenticate (see reconswarm/net/admission.py)."""
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


def bind_to_parent(every_s: float = 0.2, grace_s: float = 10.0) -> None:
    """If started by run_local.sh, die with it: no orphan outlives a run, not even a stopped one.

    When the parent dies the kernel sends this process SIGCONT (Linux PR_SET_PDEATHSIG), which wakes it if a
    fault froze it with SIGSTOP (a stopped process would never act on SIGTERM); a watcher thread then sees
    the parent gone and stops the process cleanly (SIGTERM to itself); SIGALRM ends it `grace_s` later."""
    import os

    parent = os.environ.get("RECONSWARM_DIE_WITH_PARENT")
    if not parent:
        return
    with suppress(OSError, AttributeError):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGCONT, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    threading.Thread(target=_watch_parent, args=(int(parent), every_s, grace_s), daemon=True,
                     name="watch-parent").start()


def _watch_parent(parent: int, every_s: float, grace_s: float) -> None:
    import os

    while os.getppid() == parent:  # re-parented (to init or a subreaper) once the parent is gone
        time.sleep(every_s)
    log.warning("parent %d is gone: stopping", parent)
    # The kernel ends the process grace_s from now whatever state Python is in (SIGALRM has no handler: its
    # default action terminates): a clean stop can hang in the interpreter's shutdown, where no thread runs.
    signal.alarm(max(1, round(grace_s)))
    os.kill(os.getpid(), signal.SIGTERM)


def usage() -> dict[str, float]:
    """CPU seconds, peak resident memory, samples received and loop wake-ups of this process (for logs and
    benchmarks)."""
    import resource

    ru = resource.getrusage(resource.RUSAGE_SELF)
    return {"cpu_user_s": round(ru.ru_utime, 3), "cpu_sys_s": round(ru.ru_stime, 3),
            "max_rss_mb": round(ru.ru_maxrss / 1024.0, 1), "msgs_in": Inbox.samples_in, "wakeups": Inbox.wakeups}


class StartMark:
    """Logs `usage at start: {...}` once, when the mission starts: benchmarks take CPU per tick as the exit
    line's figures minus these (start-up and imports are not per-tick work)."""

    def __init__(self) -> None:
        self.done = False

    def __call__(self, started: bool) -> None:
        if started and not self.done:
            self.done = True
            log.info("usage at start: %s", usage())


def setup_logging(debug: bool = False) -> None:
    logging.basicConfig(level=logging.DEBUG if debug else logging.INFO,
                        format="%(asctime)s %(levelname)s %(message)s", datefmt="%H:%M:%S")
