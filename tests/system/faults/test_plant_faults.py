"""Faults of the plant and the launcher (issue 11): the world frozen or killed, the record's disk full, the
launcher killed while an agent is frozen. Real processes, real signals, a real (small) filesystem."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.support import (
    PAPER,
    ROOT,
    alive,
    assert_all_gone,
    events,
    gone_within,
    launcher_cmd,
    max_difference,
    pids,
    reconswarm,
    run_launcher,
    scenario_with,
    tick_count,
    trajectories,
    wait_until,
)

pytestmark = pytest.mark.system


@pytest.mark.realtime  # (a 10 s wall-clock freeze recorded as a stall of 9-14 s)
def test_world_frozen_is_one_stall_and_lockstep_stays_exact(tmp_path: Path, out: Path) -> None:
    # The paper's scenario cut to 60 s; the world is stopped (SIGSTOP) for 10 s at t = 20.
    scen = scenario_with(tmp_path, "short.toml", PAPER.read_text(), **{"duration_s = 300.0": "duration_s = 60.0"})
    p = run_launcher(out, "-s", str(scen), "--fault", "freeze:simworld@20+10", "--json")
    assert p.returncode == 1, p.stderr[-3000:]  # not converged in 60 s: the documented "mission failed"
    s = json.loads(p.stdout)
    assert s["collisions"] == 0 and s["agents_lost"] == []
    ev = events(out / "run.db")
    assert [e["kind"] for e in ev if e["kind"] not in ("split", "merge")] == ["world_stalled"], ev
    (stall,) = [e for e in ev if e["kind"] == "world_stalled"]
    assert 19.9 <= stall["t"] <= 20.5 and 9.0 <= stall["duration_s"] <= 14.0
    # Every tick is in the record, and the trajectories are exactly those of the in-process engine.
    assert s["ticks"] == 1201 and s["record_gaps"] == [], (s["ticks"], s["record_gaps"])
    assert s["deterministic"] is True  # nobody acted on a guess: the stall was waited out, not guessed through
    sim = reconswarm("sim", str(scen), "-o", str(tmp_path / "sim"), "--json")
    assert sim.returncode == 1, sim.stderr
    assert max_difference(trajectories(out / "run.db"), trajectories(tmp_path / "sim" / "run.db")) == 0.0


def test_world_killed_is_recorded_and_printed(out: Path) -> None:
    p = run_launcher(out, "--fault", "kill:simworld@40", "--json")
    assert p.returncode == 3, p.stderr[-3000:]
    assert "simworld died (killed by SIGKILL) at t = 4" in p.stderr
    s = json.loads(p.stdout)  # the summary is printed all the same
    assert s["agents_lost"] == [] and s["end_reason"] == "world lost" and not s["converged"]
    ev = events(out / "run.db")
    (lost,) = [e for e in ev if e["kind"] not in ("split", "merge")]
    assert lost["kind"] == "world_lost" and 39.0 <= lost["t"] <= 41.0
    assert 39.0 <= s["duration_s"] <= 41.5


def test_disk_full_fails_loudly_once_and_keeps_the_record(tmp_path: Path) -> None:
    disk = tmp_path / "disk"
    disk.mkdir()
    if os.geteuid() != 0:
        pytest.skip("a small disk is a 400 kB tmpfs, which needs root to mount; CI runs as root")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=400k", "tmpfs", str(disk)], capture_output=True,
                             text=True)
    assert mounted.returncode == 0, f"as root, cannot mount a 400 kB tmpfs: {mounted.stderr.strip()}"
    out = disk / "run"
    try:
        t0 = time.monotonic()
        p = run_launcher(out, "--json", timeout=300)
        took = time.monotonic() - t0
        assert p.returncode == 3, p.stderr[-3000:]
        assert "disk full" in p.stderr, p.stderr[-3000:]
        mon_log = (out / "logs" / "monitor.log").read_text()
        assert mon_log.count("monitor up") == 1 and "disk full" in mon_log  # not restarted
        assert took < 120
        s = json.loads(p.stdout)  # the summary of what was recorded
        assert s["ticks"] > 0
        assert tick_count(out / "run.db") == s["ticks"]
        assert_all_gone(out)
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=False)


def test_launcher_killed_while_an_agent_is_frozen_leaves_no_orphan(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with (tmp_path / "launcher.log").open("wb") as log:
        launcher = subprocess.Popen(launcher_cmd(out, "--fault", "freeze:agent:2@5+600"), cwd=ROOT,
                                    stdout=log, stderr=subprocess.STDOUT)
    try:
        wait_until(lambda: (out / "faults.tsv").exists(), 180, "the freeze injected", every_s=0.2, proc=launcher)
        frozen = [int(line.split("\t")[2]) for line in (out / "processes.tsv").read_text().splitlines()
                  if line.startswith("agent\t2\t")]
        wait_until(lambda: Path(f"/proc/{frozen[0]}/stat").read_text().split()[2] == "T", 10, "agent 2 stopped")
        launcher.send_signal(signal.SIGKILL)
        launcher.wait()
        # each child stops itself within 10 s of noticing (more on a loaded machine)
        left = gone_within(pids(out), 60)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
        for p in pids(out):
            if alive(p):
                os.kill(p, signal.SIGCONT)
                os.kill(p, signal.SIGKILL)
    assert not left, f"orphans after the launcher was killed: {left}"
