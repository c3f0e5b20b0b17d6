"""Router endpoints as the machine resolves them (issue 22, cases 6 and 7), with real launches: a second
launch on `tcp/localhost:P` while one runs on `tcp/127.0.0.1:P` is refused; `tcp/[::1]:P` runs a mission."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support import ROOT, assert_all_gone, free_port, wait_for_ticks


def _launch(out: Path, router: str, *args: str) -> list[str]:
    return [sys.executable, "-m", "reconswarm_bringup.cli_launch", "--router", router, "-o", str(out), "--no-progress",
            "-n", "3", *args]


def test_localhost_is_refused_while_127_0_0_1_runs(tmp_path: Path) -> None:
    if "127.0.0.1" not in {str(sa[0]) for *_, sa in socket.getaddrinfo("localhost", 1, socket.AF_INET)}:
        pytest.skip("localhost is not 127.0.0.1 here")
    port = free_port()
    a = subprocess.Popen(_launch(tmp_path / "a", f"tcp/127.0.0.1:{port}", "--clock", "realtime", "--speed", "1"),
                         cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_for_ticks(tmp_path / "a" / "run.db", 1, a, 60)
        b = subprocess.run(_launch(tmp_path / "b", f"tcp/localhost:{port}"), cwd=ROOT, capture_output=True, text=True,
                           timeout=60)
        assert b.returncode == 2, b.stderr
        (line,) = b.stderr.strip().splitlines()
        run_a = (tmp_path / "a" / "run_id").read_text().strip()
        assert line.startswith(f"run_local: error: tcp/localhost:{port}: router in use by run {run_a}"), line
        assert a.poll() is None  # A goes on, undisturbed
    finally:
        a.send_signal(signal.SIGINT)
        a.communicate(timeout=60)
    assert a.returncode == 130
    assert_all_gone(tmp_path / "a")


def _ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as s:
            s.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback here")
def test_ipv6_loopback_router_runs_the_mission(out: Path) -> None:
    port = free_port()
    proc = subprocess.Popen(_launch(out, f"tcp/[::1]:{port}", "--json"), cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        wait_for_ticks(out / "run.db", 100, proc, 90)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, stderr[-3000:]
    s = json.loads(stdout)
    assert s["ticks"] >= 100 and s["agents_lost"] == [] and s["collisions"] == 0, stderr[-3000:]
    assert f"router up: listening on tcp/[::1]:{port}" in (out / "logs" / "router.log").read_text()


@pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback here")
def test_ipv6_loopback_with_secure_is_refused_in_one_line_for_what_it_is(tmp_path: Path) -> None:
    port = free_port()
    p = subprocess.run(_launch(tmp_path / "s", f"tcp/[::1]:{port}", "--secure"), cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 2, p.stderr
    (line,) = p.stderr.strip().splitlines()
    assert "cannot check a router's name at an IPv6 address" in line and "in use" not in line, line
