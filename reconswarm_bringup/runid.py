"""One launch, one run: a unique run id, one launch per router endpoint, no joining a live run.

Two launches on one machine must never join or disturb each other. Each launch therefore
- names its run `<scenario name>-<6 hex digits>` (the key prefix `swarm/<run>`), written to OUTDIR/run_id
  before any process starts;
- takes an exclusive lock on the router endpoint, by the socket addresses its host resolves to (a file per
  address in the temporary directory, `flock`ed for the launcher's lifetime and released by the kernel
  however it ends): a second launch on the same endpoint (`tcp/localhost:P` after `tcp/127.0.0.1:P` too) is
  refused (exit 2) with one line naming the endpoint and the run that holds it. The lock settles the
  race of two launches at the same moment too: exactly one of them gets it;
- when a router it did not start already listens there, asks it (a short liveliness query) whether the
  world of any run is alive on it (`swarm/*/alive/simworld`, as a run started by hand or from another
  machine would show) and refuses likewise if so.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import secrets
import tempfile
import time
from pathlib import Path
from typing import IO, Any

from reconswarm.errors import BadInput
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm_bringup.endpoints import socket_names

RUN_ID_FILE = "run_id"
ALIVE_WORLDS = "swarm/*/alive/simworld"


def new_run_id(scenario_name: str) -> str:
    """`<scenario name>-<6 random hex digits>`: unique per launch, a valid single key chunk."""
    return f"{scenario_name}-{secrets.token_hex(3)}"


def write_run_id(out: Path, run: str) -> Path:
    path = out / RUN_ID_FILE
    path.write_text(run + "\n")
    return path


def read_run_id(out: Path) -> str:
    """The run id a launch wrote to OUTDIR/run_id."""
    return (out / RUN_ID_FILE).read_text().strip()


class EndpointLock:
    """An exclusive lock on a router endpoint, held while the launch runs: on every socket address its host
    resolves to (`tcp/localhost:P` and `tcp/127.0.0.1:P` are one lock; whatever the protocol)."""

    def __init__(self, endpoint: str, lock_dir: Path | None = None) -> None:
        self.endpoint = endpoint
        where = lock_dir or Path(tempfile.gettempdir())
        self.paths = [where / f"reconswarm-endpoint-{re.sub(r'[^A-Za-z0-9.-]', '_', name)}.lock"
                      for name in socket_names(endpoint)]
        self.path = self.paths[0]
        self._fhs: list[IO[str]] = []

    def acquire(self, run: str) -> None:
        """Take the lock for `run`, or raise BadInput naming the run that holds it."""
        for path in self.paths:
            fh = path.open("a+")
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                fh.close()
                self.release()
                holder = self._holder(path)
                raise BadInput(f"{self.endpoint}: router in use by run {holder.get('run', '?')} (launch pid "
                               f"{holder.get('pid', '?')}); runs never share a launch's router: pass another "
                               f"--router port") from None
            fh.seek(0)
            fh.truncate()
            fh.write(json.dumps({"run": run, "pid": os.getpid()}) + "\n")
            fh.flush()
            self._fhs.append(fh)

    @staticmethod
    def _holder(path: Path) -> dict[str, Any]:
        deadline = time.monotonic() + 1.0  # the holder writes its line right after taking the lock
        while True:
            with contextlib.suppress(OSError, ValueError):
                got = json.loads(path.read_text() or "null")
                if isinstance(got, dict):
                    return got
            if time.monotonic() > deadline:
                return {}
            time.sleep(0.05)

    def release(self) -> None:
        for fh in self._fhs:
            fh.close()  # closing the descriptor releases the flock
        self._fhs = []


def live_worlds(endpoint: str, timeout_s: float = 1.5) -> list[str]:
    """Runs whose world holds its liveliness token on the router at `endpoint` (plain tcp), by run id."""
    import zenoh

    conf = ZenohOptions.build([endpoint], None, "client", None).config()
    conf.insert_json5("connect/timeout_ms", '{"router": -1, "peer": -1, "client": 3000}')
    try:
        session = zenoh.open(conf)
    except Exception:  # nothing speaks zenoh there: no run to protect
        return []
    runs: set[str] = set()
    try:
        for reply in session.liveliness().get(ALIVE_WORLDS, timeout=timeout_s):
            if reply.ok is not None:
                parts = str(reply.ok.key_expr).split("/")
                if len(parts) == 4:
                    runs.add(parts[1])
    finally:
        session.close()
    return sorted(runs)


def refuse_if_live(endpoint: str) -> None:
    """BadInput (exit 2) naming the endpoint and the live run(s) if a world is alive on that router."""
    runs = live_worlds(endpoint)
    if runs:
        raise BadInput(f"{endpoint}: the world of run {', '.join(runs)} is alive on this router; a new run "
                       f"would share its router: pass another --router port")
