"""`reconswarm sweep --dask` losing its cluster mid-sweep (a real scheduler and worker on 127.0.0.1, killed): the
scheduler lost is one line, exit 3; every worker gone is one line after a bounded wait, exit 3. Either way
results.csv keeps the rows of the runs that finished."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from reconswarm_bringup.sweep_exec import DASK_NO_WORKERS_S
from tests.support import ROOT
from tests.system.test_sweep_dask import cluster_processes

pytest.importorskip("distributed")


def _start(tmp: Path, address: str) -> tuple[subprocess.Popen[str], Path, Path]:
    s = generate(3, 1, 2)
    s = replace(s, meta=replace(s.meta, duration_s=150.0))
    path = tmp / "g.toml"
    path.write_text(to_toml(s))
    out, err = tmp / "out", tmp / "sweep.err"
    p = subprocess.Popen([sys.executable, "-m", "reconswarm_bringup.cli", "sweep", str(path), "--seeds", "0:100000",
                          "--dask", address, "-o", str(out)], cwd=ROOT, stdout=subprocess.DEVNULL,
                         stderr=err.open("w"), text=True)
    return p, out, err


def _rows(out: Path) -> int:
    try:
        with (out / "results.csv").open(newline="") as f:
            return max(0, len(list(csv.reader(f))) - 1)
    except FileNotFoundError:
        return 0


def _wait_for_rows(p: subprocess.Popen[str], out: Path, err: Path, n: int = 2, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while _rows(out) < n:
        assert p.poll() is None, err.read_text()
        assert time.monotonic() < deadline, "the sweep wrote no rows on the cluster"
        time.sleep(0.1)


def _ended(p: subprocess.Popen[str], err: Path, timeout: float) -> tuple[int, list[str]]:
    try:
        code = p.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGINT)
        p.wait(timeout=30)
        raise AssertionError(f"the sweep did not end within {timeout} s of the loss: {err.read_text()}") from None
    return code, err.read_text().strip().splitlines()


def test_the_scheduler_lost_is_one_line_exit_3(tmp_path: Path) -> None:
    with cluster_processes(tmp_path) as (address, sched, _worker):
        p, out, err = _start(tmp_path, address)
        try:
            _wait_for_rows(p, out, err)
            sched.kill()
            code, lines = _ended(p, err, 60)
        finally:
            if p.poll() is None:
                p.kill()
    assert code == 3, lines
    assert len(lines) == 1 and "scheduler" in lines[0] and address in lines[0], lines
    rows = _rows(out)
    assert rows >= 2 and f"stopped after {rows} of 100000 runs" in lines[0], lines


def test_every_worker_gone_is_one_line_after_a_bounded_wait_exit_3(tmp_path: Path) -> None:
    with cluster_processes(tmp_path) as (address, _sched, worker):
        p, out, err = _start(tmp_path, address)
        try:
            _wait_for_rows(p, out, err)
            os.killpg(worker.pid, signal.SIGKILL)  # the worker and its worker processes
            worker.wait()
            t0 = time.monotonic()
            code, lines = _ended(p, err, DASK_NO_WORKERS_S + 60)
            waited = time.monotonic() - t0
        finally:
            if p.poll() is None:
                p.kill()
    assert code == 3, lines
    assert len(lines) == 1 and "no workers" in lines[0] and address in lines[0], lines
    assert waited >= DASK_NO_WORKERS_S - 1, waited  # a worker may come back: the sweep waits that long first
