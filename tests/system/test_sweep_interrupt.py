"""A sweep never builds every job up front and never loses a finished run's row (issue 22, case 5).

A sweep of 10^8 seeds starts writing rows at once with a small, bounded memory; SIGINT (or SIGTERM) in
the middle exits 128 + signal with a line saying how many rows results.csv holds, and it holds exactly
those rows, one per finished run, each a complete row of this sweep (the previous sweep's file is gone).
"""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from reconswarm_bringup.sweep import COLUMNS
from tests.support import ROOT, gone_within, wait_until

MAX_RSS_MB = 300  # the sweep process itself; it reached 892 MB in 25 s when it built 10^8 jobs first


def _rows(path: Path) -> list[list[str]]:
    with path.open(newline="") as f:
        return list(csv.reader(f))


def _children(pid: int) -> list[int]:
    got = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        got += [int(c) for c in (task / "children").read_text().split()]
    return got


def _peak_rss_mb(pid: int) -> float:
    status = Path(f"/proc/{pid}/status").read_text()
    m = re.search(r"^VmHWM:\s+(\d+) kB", status, re.MULTILINE)
    assert m, status
    return int(m.group(1)) / 1024


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_huge_sweep_streams_and_a_signal_keeps_every_finished_row(tmp_path: Path, sig: signal.Signals) -> None:
    scen = tmp_path / "tiny.toml"
    scen.write_text(to_toml(generate(3, 1, 1)))
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.csv").write_text(",".join(COLUMNS) + "\nstale.toml,reconfigurable,7,True,1.0,0.1,0,0,1,1,0,0,1\n")
    p = subprocess.Popen([sys.executable, "-m", "reconswarm_bringup.cli", "sweep", str(scen), "--seeds", "0:100000000",
                          "--jobs", "2", "-o", str(out)], cwd=ROOT, text=True, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    try:
        wait_until(lambda: len(_rows(out / "results.csv")) >= 4, 120, "3 rows: the sweep running", every_s=0.2,
                   proc=p)  # (a header and 3 finished runs)
        assert _peak_rss_mb(p.pid) < MAX_RSS_MB
        workers = _children(p.pid)
        assert len(workers) >= 2, workers  # the two workers (and the resource tracker)
        p.send_signal(sig)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    assert p.returncode == 128 + sig, err
    m = re.search(r"stopped after (\d+) of 100000000 runs; .*results\.csv holds their (\d+) rows", err)
    assert m and m.group(1) == m.group(2), err
    assert "Traceback" not in err
    rows = _rows(out / "results.csv")
    assert tuple(rows[0]) == COLUMNS
    body = rows[1:]
    assert len(body) == int(m.group(1)) >= 3
    assert all(len(r) == len(COLUMNS) and r[0] == str(scen) for r in body)  # this sweep's, complete
    assert len({int(r[2]) for r in body}) == len(body)
    # every row is a finished run whose record is on disk
    for r in body:
        assert (out / "runs" / "tiny" / r[1] / f"seed{r[2]}" / "run.db").is_file()
    # no worker outlived the sweep
    left = gone_within(workers, 10.0)
    for w in left:
        os.kill(w, signal.SIGKILL)
    assert not left
