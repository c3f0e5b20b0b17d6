"""Timestamps along a lockstep tick's serial path (bench/tick_path.py reads them): where a tick's wall time goes.

Off unless the environment names a directory (`RECONSWARM_TRACE_DIR`); then each process keeps one row per mark
(what, tick, agent, monotonic seconds) in memory and writes them to `<dir>/<pid>.tsv` when it exits. The
monotonic clock is one clock for every process of a machine, so a put in one process and the arrival of its
sample in another subtract. A mark costs one test while tracing is off. The marks are on the project's keys:
ROS 2 mode's odometry and cmd_vel are not marked.
"""

from __future__ import annotations

import atexit
import enum
import os
import sys
import time
from pathlib import Path

ENV = "RECONSWARM_TRACE_DIR"
MAX_ROWS = 1_000_000  # (about 130 MB at most: a longer run keeps its beginning)


class Mark(enum.Enum):
    CLOCK_PUT = "clock_put"  # the world is about to put tick k's clock (the first of the tick's puts)
    STATE_PUT = "state_put"  # the world put robot a's state of tick k
    STATE_IN = "state_in"  # agent a's host took its state of tick k (the time it arrived)
    BEACON_PUT = "beacon_put"  # agent a's host put its beacon of tick k
    BEACON_IN = "beacon_in"  # a host took agent a's beacon of tick k from another process (the time it arrived)
    CMD_PUT = "cmd_put"  # agent a's host put its command of tick k
    CMD_IN = "cmd_in"  # the world took agent a's command of tick k (the time it arrived)
    # One per message of a host (a: the host's id, its lowest agent's; k: its first row's tick).
    HOST_STATE_PUT = "host_state_put"  # the world put a message of host a's states of tick k
    HOST_STATE_IN = "host_state_in"  # host a took a message of its states of tick k (the time it arrived)
    HOST_CMD_PUT = "host_cmd_put"  # host a put a message of its agents' commands
    HOST_CMD_IN = "host_cmd_in"  # the world took a message of host a's commands (the time it arrived)


_dir = os.environ.get(ENV) or None
_rows: list[tuple[str, int, int, float]] = []


def mark(what: Mark, k: int, agent: int, at_s: float | None = None) -> None:
    """Note `what` for tick k and agent (0: none) at at_s (None: now), if tracing is on."""
    if _dir is not None and len(_rows) < MAX_ROWS:
        _rows.append((what.value, k, agent, time.monotonic() if at_s is None else at_s))


def write(directory: str | None = None) -> Path | None:
    """The rows so far into `<directory>/<pid>.tsv` (what, tick, agent, seconds), if any; the file written."""
    where = directory or _dir
    if where is None or not _rows:
        return None
    path = Path(where) / f"{os.getpid()}.tsv"
    try:
        with path.open("w") as f:
            f.writelines(f"{what}\t{k}\t{agent}\t{t:.7f}\n" for what, k, agent, t in _rows)
    except OSError as exc:  # (at exit: one line, the process's own outcome stands)
        print(f"{ENV}={where}: cannot write the trace: {exc.strerror or exc}", file=sys.stderr)
        return None
    return path


def start(directory: str | None) -> None:
    """Trace into `directory` from now on (None: stop); the rows are written at exit."""
    global _dir
    _dir = directory
    _rows.clear()


atexit.register(write)
