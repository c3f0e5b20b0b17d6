"""Bad launch input refused in one line, exit 2, before anything starts (issue 22, case 8): a router endpoint
with ?metadata or #config, a non-ASCII digit in ROS_DOMAIN_ID, a --foxglove port that is the router's or in
use."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support import ROOT, free_port, pids

pytestmark = pytest.mark.parallel  # (refused before anything starts: beside the unit tests)


def _launch(out: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli_launch", "-o", str(out), "--no-progress",
                           "-n", "3", *args], cwd=ROOT, capture_output=True, text=True, timeout=60, env=env)


def _one_line(p: subprocess.CompletedProcess[str], *words: str) -> None:
    assert p.returncode == 2, p.stderr
    (line,) = p.stderr.strip().splitlines()
    assert line.startswith("run_local: error: ") and "Traceback" not in p.stderr, p.stderr
    for w in words:
        assert w in line, line


@pytest.mark.parametrize("tail", ["?x=1", "#x=1"])
def test_router_with_metadata_or_config(tmp_path: Path, tail: str) -> None:
    port = free_port()
    _one_line(_launch(tmp_path, "--router", f"tcp/127.0.0.1:{port}{tail}"), "--router", tail)
    assert pids(tmp_path) == []


def test_ros_domain_id_with_a_non_ascii_digit(tmp_path: Path) -> None:
    env = dict(os.environ, ROS_DOMAIN_ID="²")
    _one_line(_launch(tmp_path, "--router", f"tcp/127.0.0.1:{free_port()}", "--ros2", env=env), "ROS_DOMAIN_ID",
              "'²'")


def test_foxglove_on_the_routers_port(tmp_path: Path) -> None:
    port = free_port()
    _one_line(_launch(tmp_path, "--router", f"tcp/127.0.0.1:{port}", "--foxglove", str(port)),
              f"--foxglove {port}", "router's port")
    assert pids(tmp_path) == []


def test_foxglove_on_a_port_in_use(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        busy = s.getsockname()[1]
        _one_line(_launch(tmp_path, "--router", f"tcp/127.0.0.1:{free_port()}", "--foxglove", str(busy)),
                  f"--foxglove {busy}", "in use")
    assert pids(tmp_path) == []
