"""Where a sweep's runs execute: worker processes on this machine, or a Dask cluster (`--dask ADDRESS`).

Each is a context manager yielding (executor, slots): a `concurrent.futures.Executor` for
`sweep.stream` and how many runs it executes at once (the sweep keeps twice that many in flight, so a
worker never waits for the next job and a sweep of 10^8 seeds never holds more than that).
"""

from __future__ import annotations

import contextlib
import signal
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


@contextlib.contextmanager
def dask(address: str, timeout_s: float = DASK_CONNECT_TIMEOUT_S) -> Iterator[tuple[Executor, int]]:
    """The Dask cluster whose scheduler is at `address` (tcp://host:port); BadInput if the `distributed`
    package is missing or no scheduler answers there within timeout_s."""
    try:
        from distributed import Client
    except ImportError:
        raise BadInput("--dask: needs the 'distributed' package (pip install -e '.[dask]')") from None
    try:
        client = Client(address, timeout=timeout_s, set_as_default=False)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
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
