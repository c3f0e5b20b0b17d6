"""Where a sweep's runs execute: worker processes on this machine, or a Dask cluster (`--dask ADDRESS`).

Each is a context manager yielding (executor, slots, check): a `concurrent.futures.Executor` for
`sweep.stream`, how many runs it executes at once (the sweep keeps twice that many in flight, so a
worker never waits for the next job and a sweep of 10^8 seeds never holds more than that), and the check
`sweep.stream` calls while it waits (None: nothing to watch). A Dask cluster's losses end the sweep with
one line (ProcessFailure, exit 3): the scheduler lost at once, no worker left after DASK_NO_WORKERS_S (one
may come back); `distributed`'s own logging is silenced meanwhile (its tracebacks say the same at length).
"""

from __future__ import annotations

import contextlib
import logging
import signal
import socket
import sys
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from multiprocessing import get_context
from typing import Any

from reconswarm.errors import BadInput, ProcessFailure

DASK_CONNECT_TIMEOUT_S = 5.0
DASK_NO_WORKERS_S = 20.0  # how long a sweep waits for a worker when the cluster has none left


def _worker_init() -> None:
    # A terminal's Ctrl-C reaches the whole process group: the sweep process decides (it stops the
    # workers), a worker does not print a KeyboardInterrupt traceback of its own.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class _Pool(ProcessPoolExecutor):
    def terminate(self) -> None:
        """Stop the workers now (an interrupted sweep does not wait for the runs under way)."""
        for proc in list((getattr(self, "_processes", None) or {}).values()):
            with contextlib.suppress(OSError, ValueError):
                proc.terminate()


Where = Iterator[tuple[Executor, int, Callable[[], None] | None]]


@contextlib.contextmanager
def local(workers: int) -> Where:
    """`workers` processes, spawned clean (no inherited threads or sessions)."""
    pool = _Pool(workers, mp_context=get_context("spawn"), initializer=_worker_init)
    try:
        yield pool, workers, None
    except BaseException:
        pool.terminate()
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _scheduler(address: str) -> tuple[str, int]:
    """`tcp://HOST:PORT` (or `HOST:PORT`) -> (host, port); BadInput otherwise."""
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    host, colon, port = rest.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    digits = port.isascii() and port.isdigit()
    if scheme != "tcp" or not colon or not host or not digits or not 1 <= int(port) <= 65535:
        raise BadInput(f"--dask: expected a scheduler address tcp://HOST:PORT, got {address!r}")
    return host, int(port)


@contextlib.contextmanager
def dask(address: str, timeout_s: float = DASK_CONNECT_TIMEOUT_S) -> Where:
    """The Dask cluster whose scheduler is at `address` (tcp://host:port); BadInput if the `distributed`
    package is missing or no scheduler answers there within timeout_s."""
    host, port = _scheduler(address)
    try:
        from distributed import Client
    except ImportError:
        raise BadInput("--dask: needs the 'distributed' package (pip install -e '.[dask]')") from None
    try:  # a plain connection first: nothing listening is said at once, in our words
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        raise BadInput(f"--dask {address}: no Dask scheduler answers there ({exc.strerror or exc})") from None
    try:
        client = Client(address, timeout=timeout_s, set_as_default=False)
    except Exception as exc:  # something listens there, but it is not a Dask scheduler that answers
        # (distributed's half-made client then complains from its __del__ as the process exits: not ours to show)
        sys.unraisablehook = lambda _unraisable: None
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise BadInput(f"--dask {address}: no Dask scheduler answers there ({reason})") from None
    try:
        if not client.nthreads():
            try:
                client.wait_for_workers(1, timeout=timeout_s)
            except (TimeoutError, OSError):
                raise BadInput(f"--dask {address}: the scheduler has no workers") from None
        slots = sum(client.nthreads().values())
    except BaseException:
        client.close()
        raise
    watch = _Watch(client, address)
    with _quiet("distributed", "tornado", "asyncio"):  # (closing a client that lost its scheduler logs too)
        try:
            yield client.get_executor(pure=False), slots, watch.check
        except (KeyboardInterrupt, ProcessFailure):
            raise
        except BaseException as exc:  # the runs the scheduler took with it are cancelled
            if client.status != "running":
                raise watch.lost() from None
            raise exc
        finally:
            client.close()


class _Watch:
    """A Dask cluster's health, as seen from its client (checked about once a second by sweep.stream)."""

    def __init__(self, client: Any, address: str, grace_s: float = DASK_NO_WORKERS_S) -> None:
        self.client, self.address, self.grace_s = client, address, grace_s
        self._none_since: float | None = None

    def lost(self) -> ProcessFailure:
        return ProcessFailure(f"sweep: lost the Dask scheduler at {self.address} (its runs under way are lost)")

    def check(self) -> None:
        if self.client.status != "running":
            raise self.lost()
        workers = self.client.scheduler_info(n_workers=0).get("n_workers")
        if workers or workers is None:
            self._none_since = None
            return
        now = time.monotonic()
        if self._none_since is None:
            self._none_since = now
        elif now - self._none_since >= self.grace_s:
            raise ProcessFailure(f"sweep: the Dask cluster at {self.address} has had no workers for "
                                 f"{self.grace_s:.0f} s (they died or left)")


@contextlib.contextmanager
def _quiet(*loggers: str) -> Iterator[None]:
    """These loggers (and theirs) say nothing while the sweep runs; their levels are restored after."""
    saved = {name: logging.getLogger(name).level for name in logging.root.manager.loggerDict
             if any(name == n or name.startswith(n + ".") for n in loggers)}
    saved.update({n: logging.getLogger(n).level for n in loggers})
    for name in saved:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for name, level in saved.items():
            logging.getLogger(name).setLevel(level)
