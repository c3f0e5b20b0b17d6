"""A process's life around its loop: signals, dying with its launcher, usage figures, logging."""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections.abc import Callable
from contextlib import suppress
from typing import Any

from reconswarm.net.runtime.inbox import Inbox

log = logging.getLogger("reconswarm")


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
    line's figures minus these (start-up and imports are not per-tick work); and whom the session is connected to
    then (`zenoh at start: 1 router, 3 peers`)."""

    def __init__(self, links: Callable[[], str] | None = None) -> None:
        self.done, self.links = False, links

    def __call__(self, started: bool) -> None:
        if started and not self.done:
            self.done = True
            log.info("usage at start: %s", usage())
            if self.links is not None:
                log.info("zenoh at start: %s", self.links())


def setup_logging(debug: bool = False) -> None:
    logging.basicConfig(level=logging.DEBUG if debug else logging.INFO,
                        format="%(asctime)s %(levelname)s %(message)s", datefmt="%H:%M:%S")
