"""Where a sweep's runs execute: worker processes on this machine, or a Dask cluster (`--dask ADDRESS`).

Each is a context manager yielding (executor, slots): a `concurrent.futures.Executor` for
`sweep.stream` and how many runs it executes at once (the sweep keeps twice that many in flight, so a
worker never waits for the next job and a sweep of 10^8 seeds never holds more than that).
"""

from __future__ import annotations

import contextlib
import signal
import socket
import sys
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from multiprocessing import get_context

from reconswarm.errors import BadInput

DASK_CONNECT_TIMEOUT_S = 5.0


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


@contextlib.contextmanager
def local(workers: int) -> Iterator[tuple[Executor, int]]:
    """`workers` processes, spawned clean (no inherited threads or sessions)."""
    pool = _Pool(workers, mp_context=get_context("spawn"), initializer=_worker_init)
    try:
        yield pool, workers
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
def dask(address: str, timeout_s: float = DASK_CONNECT_TIMEOUT_S) -> Iterator[tuple[Executor, int]]:
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
        yield client.get_executor(pure=False), slots
    finally:
        client.close()
