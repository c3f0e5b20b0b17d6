"""ROS 2 mode on a machine behind the clock: the paper with one process per agent at `--speed 8` (a period of
6.25 ms: on 2 cores the agents cannot plan within it). No attacker and no fault: whatever the machine, no robot
may be driven by a late plan into another or into an obstacle (agents send no cmd_vel planned from odometry older
than a period, and the plant holds each from where its robot stood when it was planned: docs/ros2.md).
Measured on 2 cores, 2026-12-04: before that rule 29 contacts and 41 safety violations (58.7 % of deadlines
missed); with it 0 and 0 (the robots mostly stand: 99.6 % missed, not converged)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.support import PAPER, run_launcher


def test_a_ros2_mission_behind_the_clock_stops_its_robots_rather_than_collide(out: Path) -> None:
    p = run_launcher(out, "-s", str(PAPER), "--ros2", "--speed", "8", "--json", timeout=600)
    assert p.returncode in (0, 1), p.stderr[-3000:]  # (1: not converged, as on a machine this far behind)
    s = json.loads(p.stdout)
    assert s["finished"] and s["mode"] == "realtime", s
    assert s["collisions"] == 0 and s["safety_violations"] == 0, (s["collisions"], s["missed_deadline_ratio"])
    # Nothing refused: no intrusion, no cmd_vel dated "sent after any odometry" (one machine: one clock).
    assert s["intrusions"] == 0 and s["messages_rejected"] == 0 and s["agents_lost"] == [], s
