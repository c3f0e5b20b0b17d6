"""ROS 2 mode on a machine behind the clock: the paper with one process per agent at `--speed 8` (a period of
6.25 ms: on 2 cores the agents cannot plan within it). No attacker and no fault: whatever the machine, no robot
may be driven by a late plan into another or into an obstacle (agents send no cmd_vel planned from odometry older
than a period, and the plant holds each from where its robot stood when it was planned: docs/ros2.md).
Measured on 2 cores, 2026-12-04: before that rule 29 contacts and 41 safety violations (58.7 % of deadlines
missed); with it 0 and 0 (the robots mostly stand: 99.6 % missed, not converged). Nor may the world take agents
that only plan late for lost: a machine further behind (CI's, or this one with 3 busy processes beside the run)
had every agent withhold its cmd_vels for seconds, the world count them gone and end the mission (no agents), and
their new sessions count as impersonators (50 intrusions); agents now send a stop once their robot's hold is over,
then every 0.5 s (agent/ros2_io.py), and a new session keeps the old one's id."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.support import PAPER, run_launcher

pytestmark = pytest.mark.realtime  # (holds only if the machine keeps the clock's pace: run alone, last)


def test_a_ros2_mission_behind_the_clock_stops_its_robots_rather_than_collide(out: Path) -> None:
    p = run_launcher(out, "-s", str(PAPER), "--ros2", "--speed", "8", "--json", timeout=600)
    assert p.returncode in (0, 1), p.stderr[-3000:]  # (1: not converged, as on a machine this far behind)
    s = json.loads(p.stdout)
    assert s["finished"] and s["mode"] == "realtime", s
    assert s["collisions"] == 0 and s["safety_violations"] == 0, (s["collisions"], s["missed_deadline_ratio"])
    # Nothing refused: no intrusion, no cmd_vel dated "sent after any odometry" (one machine: one clock).
    assert (s["intrusions"], s["messages_rejected"], s["agents_lost"]) == (0, 0, []), (
        s["intrusions_by_kind"], s["messages_rejected_by_process"], (out / "logs" / "simworld.log").read_text()[-3000:])
    assert s["duration_s"] == 300.0, s  # (the scenario's whole duration: the mission did not end for want of agents)
