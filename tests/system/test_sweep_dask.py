"""`reconswarm sweep --dask ADDRESS` (issue 20, deliverable 7): the sweep on a real Dask cluster (a
scheduler and two worker processes started here on 127.0.0.1, free ports) gives the rows of the same
sweep on local processes, apart from wall time; an address where no scheduler answers is one line, exit 2.
"""

from __future__ import annotations

import contextlib
import csv
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from reconswarm_bringup.sweep import COLUMNS
from tests.support import ROOT, free_port, reconswarm, wait_until

pytest.importorskip("distributed")
DASK = shutil.which("dask") or str(Path(__import__("sys").executable).with_name("dask"))


def _stop(p: subprocess.Popen[bytes]) -> None:
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(timeout=15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


@contextlib.contextmanager
def cluster(tmp: Path) -> Iterator[str]:
    """A scheduler and a worker with two processes of one thread each, on 127.0.0.1: its address."""
    with cluster_processes(tmp) as (address, _sched, _worker):
        yield address


@contextlib.contextmanager
def cluster_processes(tmp: Path) -> Iterator[tuple[str, subprocess.Popen[bytes], subprocess.Popen[bytes]]]:
    """As cluster(), with the scheduler's and the worker's processes (the worker in a process group of its own,
    its worker processes with it)."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = (tmp / "scheduler.log").open("wb"), (tmp / "worker.log").open("wb")
    sched = subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                             cwd=ROOT, stdout=logs[0], stderr=subprocess.STDOUT)
    worker = subprocess.Popen([DASK, "worker", address, "--host", "127.0.0.1", "--nworkers", "2", "--nthreads", "1",
                               "--no-dashboard", "--memory-limit", "0", "--local-directory", str(tmp / "dask")],
                              cwd=ROOT, stdout=logs[1], stderr=subprocess.STDOUT, start_new_session=True)
    try:
        from distributed import Client

        deadline = time.monotonic() + 60

        def both_workers() -> bool:  # the scheduler up and both worker processes registered
            try:
                with Client(address, timeout=2, set_as_default=False) as c:
                    c.wait_for_workers(2, timeout=max(1.0, deadline - time.monotonic()))
                    return True
            except OSError:
                return False

        wait_until(both_workers, 60, f"the scheduler up and 2 workers: {tmp / 'scheduler.log'}", every_s=0.3,
                   proc=sched)
        yield address, sched, worker
    finally:
        _stop(worker)
        _stop(sched)
        for f in logs:
            f.close()


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def test_dask_sweep_rows_equal_the_local_sweep(tmp_path: Path) -> None:
    s = generate(3, 1, 2)
    s = replace(s, meta=replace(s.meta, duration_s=150.0))
    path = tmp_path / "g.toml"
    path.write_text(to_toml(s))
    args = ["sweep", str(path), "--seeds", "0:2", "--planner", "reconfigurable,virtual-leader"]
    local = reconswarm(*args, "--jobs", "2", "-o", str(tmp_path / "local"))
    assert local.returncode == 0, local.stderr
    with cluster(tmp_path) as address:
        remote = reconswarm(*args, "--dask", address, "-o", str(tmp_path / "dask"))
    assert remote.returncode == 0, remote.stderr
    assert f"on the Dask cluster at {address}" in remote.stdout
    a, b = _rows(tmp_path / "local"), _rows(tmp_path / "dask")
    assert len(a) == len(b) == 2 * 2
    strip = [c for c in COLUMNS if c != "wall_time_s"]
    assert [[r[c] for c in strip] for r in a] == [[r[c] for c in strip] for r in b]  # same rows, same order
    assert all(float(r["wall_time_s"]) > 0 for r in b)
    # the same per-planner table
    table = [ln for ln in local.stdout.splitlines() if "reconfigurable" in ln or "virtual-leader" in ln]
    assert table and table == [ln for ln in remote.stdout.splitlines() if "reconfigurable" in ln
                               or "virtual-leader" in ln]
    for r in b:  # the workers wrote each run's record where the sweep says
        assert (tmp_path / "dask" / "runs" / Path(r["scenario"]).stem / r["planner"] / f"seed{r['seed']}"
                / "run.db").is_file()


def test_no_scheduler_there_is_one_line_exit_2(tmp_path: Path) -> None:
    scen = tmp_path / "g.toml"
    scen.write_text(to_toml(generate(3, 1, 1)))
    for address in (f"tcp://127.0.0.1:{free_port()}", "127.0.0.1", "udp://127.0.0.1:8786"):
        r = reconswarm("sweep", str(scen), "--dask", address, "-o", str(tmp_path / "out"), timeout=60)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2, r.stderr
        assert len(lines) == 1 and "--dask" in lines[0], lines
        assert not (tmp_path / "out" / "results.csv").exists()
