"""What a launch tells its user (issue 21, items 4 and 5), with real processes: a run stopped by SIGINT,
SIGTERM or --timeout still prints the summary and the record's path, and the record says why it ended;
--foxglove prints the live view's URL once it listens, --ros2 the router and domain ROS 2 tools need."""

from __future__ import annotations

import json
import signal
import subprocess
from pathlib import Path

import pytest

from tests.support import ROOT, free_port, launcher_cmd, summary, wait_for_ticks


def _stop_mid_run(out: Path, sig: signal.Signals, *args: str) -> subprocess.CompletedProcess[str]:
    port = free_port()
    proc = subprocess.Popen(launcher_cmd(out, "-n", "3", *args, port=port), cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        wait_for_ticks(out / "run.db", 20, proc, 60, "the run did not start")
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_stopped_run_prints_its_summary_and_says_stopped(out: Path, sig: signal.Signals) -> None:
    p = _stop_mid_run(out, sig, "--clock", "realtime", "--speed", "1")
    assert p.returncode == 128 + sig, p.stderr[-3000:]
    assert f"record: {out / 'run.db'}" in p.stdout and "end_reason" in p.stdout and "stopped" in p.stdout
    assert f"stopped by signal {int(sig)}" in p.stderr
    s = summary(out / "run.db")
    assert s["end_reason"] == "stopped" and s["finished"] is False and s["ticks"] >= 20


def test_a_timeout_prints_its_summary_says_timeout_and_the_live_view_url(out: Path) -> None:
    live = free_port()
    cmd = launcher_cmd(out, "-n", "3", "--clock", "realtime", "--speed", "1", "--timeout", "12", "--json",
                       "--foxglove", str(live))
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 3, p.stderr[-3000:]
    assert "timeout after 12 s of wall time" in p.stderr
    s = json.loads(p.stdout)  # the summary, as JSON with --json
    assert s["end_reason"] == "timeout" and s["finished"] is False and not s["converged"]
    assert summary(out / "run.db")["end_reason"] == "timeout"
    assert f"run_local: live view: ws://127.0.0.1:{live} " in p.stderr, p.stderr[-3000:]


def test_ros2_prints_the_router_and_the_domain(out: Path) -> None:
    port = free_port()
    proc = subprocess.Popen(launcher_cmd(out, "-n", "3", "--ros2", "--ros-domain-id", "17", port=port), cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for_ticks(out / "run.db", 5, proc, 60)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    ep = f"tcp/127.0.0.1:{port}"
    assert f"run_local: ROS 2: topics /robot_<i>/odom and /robot_<i>/cmd_vel in domain 17 on the Zenoh router {ep}" \
        in stderr, stderr[-3000:]
    assert ("run_local: ROS 2 tools: export RMW_IMPLEMENTATION=rmw_zenoh_cpp ROS_DOMAIN_ID=17 "
            f"ZENOH_CONFIG_OVERRIDE='connect/endpoints=[\"{ep}\"]'; ros2 topic list") in stderr
    assert proc.returncode == 130 and f"record: {out / 'run.db'}" in stdout
