"""`monitor export --format csv`: a run's trajectories, `t_s,agent,px_m,py_m,theta_rad`, one row per agent per
tick (an agent with no known state at a tick has no row there)."""

from __future__ import annotations

import csv
from collections.abc import Callable
from typing import TextIO

import numpy as np

from reconswarm.record.store import RunRecord, Ticks

HEADER = ("t_s", "agent", "px_m", "py_m", "theta_rad")


def export_csv(rec: RunRecord, stream: TextIO, progress: Callable[[int, int], None] | None = None,
               ticks: Ticks | None = None) -> int:
    """Write the trajectories to stream; return the number of rows. progress(done, total ticks) now and then.
    ticks: rec.ticks() when the caller read them already (a damaged record refused before anything is written)."""
    tk = rec.ticks() if ticks is None else ticks
    ids = [int(a) for a in rec.ids]
    w = csv.writer(stream, lineterminator="\n")
    w.writerow(HEADER)
    rows = 0
    n = int(tk.t.size)
    for row in range(n):
        t = f"{tk.t[row]:.6f}"
        known = np.isfinite(tk.px[row])
        for col in np.flatnonzero(known).tolist():
            w.writerow([t, ids[col], repr(float(tk.px[row, col])), repr(float(tk.py[row, col])),
                        repr(float(tk.theta[row, col]))])
        rows += int(known.sum())
        if progress is not None and row % 200 == 0:
            progress(row, n)
    if progress is not None:
        progress(n, n)
    return rows
