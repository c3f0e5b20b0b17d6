"""`monitor export --format csv`: a run's trajectories, `t_s,agent,px_m,py_m,theta_rad`, one row per agent per
tick (an agent with no known state at a tick has no row there)."""

from __future__ import annotations

import csv
from collections.abc import Callable
from typing import TextIO

import numpy as np

from reconswarm.record.store import RunRecord, Ticks

HEADER = ("t_s", "agent", "px_m", "py_m", "theta_rad")
CHUNK_TICKS = 500  # ticks formatted and written at once


def export_csv(rec: RunRecord, stream: TextIO, progress: Callable[[int, int], None] | None = None,
               ticks: Ticks | None = None) -> int:
    """Write the trajectories to stream; return the number of rows. progress(done, total ticks) now and then.
    ticks: rec.ticks() when the caller read them already (a damaged record refused before anything is written)."""
    tk = rec.ticks() if ticks is None else ticks
    ids = np.asarray([int(a) for a in rec.ids], dtype=np.int64)
    w = csv.writer(stream, lineterminator="\n")
    w.writerow(HEADER)
    rows = 0
    n = int(tk.t.size)
    for start in range(0, n, CHUNK_TICKS):  # in bulk: the known (tick, agent) cells of a chunk of ticks at once
        stop = min(n, start + CHUNK_TICKS)
        r, c = np.nonzero(np.isfinite(tk.px[start:stop]))
        r += start
        times = [f"{v:.6f}" for v in tk.t[start:stop].tolist()]
        # (the csv module writes a float as repr writes it: the shortest text that reads back the same number)
        w.writerows(zip([times[k - start] for k in r.tolist()], ids[c].tolist(), tk.px[r, c].tolist(),
                        tk.py[r, c].tolist(), tk.theta[r, c].tolist(), strict=True))
        rows += int(r.size)
        if progress is not None:
            progress(stop, n)
    if progress is not None and n == 0:
        progress(0, 0)
    return rows
