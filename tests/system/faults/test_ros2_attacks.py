"""ROS 2 mode attacked from an outside zenoh session with no credentials (issue 20): robot 3's odometry
replayed shifted by 40 m, a forged cmd_vel driving robot 3 onto robot 5 (rosbags CDR, a hand-packed 33-byte
attachment), cmd_vel at v = 1.7e308 m/s for robot 7, and a liveliness token held for agent 3 while agent 3
is killed. Short runs of the paper mission (real time; `RUNS`: the forged odometry and cmd_vel share one) on a
router at 127.0.0.1: the run keeps its robots apart, no process dies, and every refused forgery is counted with
the attacker's session as its source; the dead agent is dropped by the world although a token stands for it."""

from __future__ import annotations

import json
import math
import struct
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest
import zenoh

from reconswarm.net.ros2 import ros2
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import batch_from_wire
from reconswarm.net.wire.keys import Keys
from tests.support import (
    PAPER,
    ROOT,
    end_launch,
    free_port,
    launcher_cmd,
    paper_with,
    read_run_id,
    wait_for_ticks,
    wait_until,
)
from tests.system.faults.test_intrusions import refused_from

pytestmark = pytest.mark.realtime  # (holds only if the machine keeps the clock's pace: run alone, last)

DOMAIN = 11
DURATION_S = 36.0
ATTACK_FROM_S = 4.0  # simulated: the attack starts once the mission has run this long
ATTACK_WALL_S = 20.0
KILL_AT_S = 8.0


class Outsider:
    """A plain client on the run's router: follows the truth and the clock, publishes ROS 2 samples with a
    hand-packed attachment under its own random gid."""

    def __init__(self, endpoint: str, run: str) -> None:
        self.z: Any = zenoh.open(ZenohOptions.build([endpoint], None, "client", None).config())
        self.zid = str(self.z.zid())
        self.keys = Keys(run)
        self.gid, self.seq = bytes(range(16)), 0
        self.lock = threading.Lock()
        self.truth: wire.Truth | None = None
        self.clocks: list[wire.Clock] = []
        self.head3: dict[int, tuple[float, float]] = {}  # tick -> robot 3's head point, by the world's truth
        self.beacons3: list[wire.Beacon] = []  # agent 3's idea of its robot, as it tells its peers
        self.subs = [self.z.declare_subscriber(self.keys.truth, self._on_truth),
                     self.z.declare_subscriber(self.keys.clock, self._on_clock),
                     self.z.declare_subscriber(self.keys.host_beacons(None, None), self._on_beacon)]
        self.sent = 0

    def _on_truth(self, s: Any) -> None:
        tr = wire.truth_from_wire(s.payload.to_bytes())
        i3 = tr.ids.index(3)
        with self.lock:
            self.truth = tr
            self.head3[tr.k] = (tr.px[i3], tr.py[i3])

    def _on_beacon(self, s: Any) -> None:
        got = [b for b in batch_from_wire(s.payload.to_bytes()).beacons if b.id == 3]  # (its host's batches)
        with self.lock:
            self.beacons3 += got

    def idea_off_m(self) -> float:
        """How far agent 3's beacons put its robot from where the world has it, at the same tick (the largest)."""
        with self.lock:
            return max((math.hypot(b.px - self.head3[b.k][0], b.py - self.head3[b.k][1]) for b in self.beacons3
                        if b.k in self.head3), default=math.nan)

    def _on_clock(self, s: Any) -> None:
        c = wire.clock_from_wire(s.payload.to_bytes())
        with self.lock:
            self.clocks.append(c)

    def now(self) -> wire.Truth:
        def truth() -> wire.Truth | None:
            with self.lock:
                return self.truth

        return wait_until(truth, 60.0, "the world's truth heard", every_s=0.02)

    def put_ros2(self, key: str, payload: bytes) -> None:
        self.seq += 1
        self.z.put(key, payload, attachment=struct.pack("<qqB16s", self.seq, time.time_ns(), 16, self.gid))
        self.sent += 1

    def close(self) -> None:
        self.z.close()


def _forge_odometry(o: Outsider, until: float) -> None:
    """Robot 3's odometry, overheard and replayed 40 m to the east, as fast as it comes."""
    key = ros2.odom_key(DOMAIN, 3)
    heard: list[bytes] = []
    sub = o.z.declare_subscriber(key, lambda s: heard.append(s.payload.to_bytes()),  # (not our own forgeries)
                                 allowed_origin=zenoh.Locality.REMOTE)
    while time.monotonic() < until:
        while heard:
            real = ros2.odom_from_ros(heard.pop(0), 3)
            fake = ros2.Odom(3, real.t_s, real.x_m + 40.0, real.y_m, real.theta_rad, real.v_mps, real.omega_radps)
            o.put_ros2(key, ros2.odom_to_ros(fake))
        time.sleep(0.005)
    sub.undeclare()


def _forge_cmd_vel(o: Outsider, until: float) -> None:
    """robot 3 steered onto robot 5 at 30 m/s, 100 cmd_vel a second (4 in each 50 ms tick)."""
    key = ros2.cmd_vel_key(DOMAIN, 3)
    while time.monotonic() < until:
        tr = o.now()
        i3, i5 = tr.ids.index(3), tr.ids.index(5)
        bearing = math.atan2(tr.py[i5] - tr.py[i3], tr.px[i5] - tr.px[i3])
        turn = math.remainder(bearing - tr.theta[i3], 2 * math.pi)
        o.put_ros2(key, ros2.twist_to_ros(30.0, 4.0 * turn))
        time.sleep(0.01)


def _absurd_cmd_vel(o: Outsider, until: float) -> None:
    """40 cmd_vel at v = 1.7e308 m/s for robot 7 (rosbags' CDR, as any ROS 2 tool packs it)."""
    store = ros2._store()
    vec = store.types["geometry_msgs/msg/Vector3"]
    raw = bytes(store.serialize_cdr(store.types[ros2.TWIST](linear=vec(1.7e308, 0.0, 0.0), angular=vec(0.0, 0.0, 0.0)),
                                    ros2.TWIST, little_endian=True))
    for _ in range(40):
        o.put_ros2(ros2.cmd_vel_key(DOMAIN, 7), raw)
        time.sleep(0.01)


def _token_for_dead_agent(o: Outsider, until: float) -> None:
    """A second liveliness token for agent 3 (which the launcher kills at KILL_AT_S), held to the end."""
    token = o.z.liveliness().declare_token(o.keys.alive_agent(3))
    while time.monotonic() < until:
        time.sleep(0.1)
    token.undeclare()


ATTACKS = {"odometry": _forge_odometry, "cmd_vel": _forge_cmd_vel, "absurd": _absurd_cmd_vel,
           "token": _token_for_dead_agent}


# Each attack's run: the mission's simulated seconds, and the attack's wall seconds from ATTACK_FROM_S on. The
# forged odometry and the forged cmd_vel go at one run from two outside sessions (each forgery is counted against
# its own session's id, at its own addressee); the absurd cmd_vel (40 samples, 0.4 s) and the token held for a
# dead agent (killed: the run's outcome differs) have a run each, as long as what they check needs.
RUNS: dict[tuple[str, ...], tuple[float, float]] = {("odometry", "cmd_vel"): (DURATION_S, ATTACK_WALL_S),
                                                    ("absurd",): (12.0, 1.0),
                                                    ("token",): (20.0, 16.0)}


def _run(tmp: Path, attacks: tuple[str, ...]) -> tuple[dict[str, Any], dict[str, Outsider], int]:
    duration_s, attack_wall_s = RUNS[attacks]
    out = tmp / "run"
    port = free_port()
    scenario = paper_with(tmp, **{"duration_s = 300.0": f"duration_s = {duration_s}"})
    extra = ["--fault", f"kill:agent:3@{KILL_AT_S:g}"] if "token" in attacks else []
    err = tmp / "launcher.err"
    with err.open("wb") as fh:
        proc = subprocess.Popen(launcher_cmd(out, "-s", str(scenario), "--ros2", "--ros-domain-id", str(DOMAIN),
                                             "--json", *extra, port=port), cwd=ROOT, stdout=subprocess.PIPE, stderr=fh)
    outs: dict[str, Outsider] = {}
    try:
        wait_for_ticks(out / "run.db", round(ATTACK_FROM_S / 0.05), proc, 120, lambda: err.read_text()[-2000:])
        for attack in attacks:
            outs[attack] = Outsider(f"tcp/127.0.0.1:{port}", read_run_id(out))
        until = time.monotonic() + attack_wall_s
        threads = [threading.Thread(target=ATTACKS[a], args=(outs[a], until)) for a in attacks]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        stdout, _ = proc.communicate(timeout=180)
    finally:
        end_launch(proc, out, *outs.values())
    assert proc.returncode in (0, 1) and stdout.strip(), err.read_text()[-3000:]  # (1: not converged so soon)
    s = json.loads(stdout)
    print(attacks, "sent:", {a: o.sent for a, o in outs.items()}, "summary:", {k: s.get(k) for k in (
        "duration_s", "end_reason", "converged", "collisions", "min_agent_gap_m", "agents_lost", "intrusions",
        "intrusions_by_kind", "messages_rejected_by_process")})
    assert s["duration_s"] >= duration_s - 0.1 and s["end_reason"] == "duration", s  # the mission ran its course
    return s, outs, proc.returncode


@pytest.fixture(scope="module")
def forged(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], dict[str, Outsider], Path]:
    tmp = tmp_path_factory.mktemp("forged")
    s, outs, _ = _run(tmp, ("odometry", "cmd_vel"))
    return s, outs, tmp / "run" / "run.db"


def test_forged_odometry_cannot_move_an_agents_idea_of_its_robot(forged: tuple[dict, dict, Path]) -> None:
    s, outs, db = forged
    o = outs["odometry"]
    assert o.sent > 100
    off = o.idea_off_m()
    print(f"agent 3's beacons ({len(o.beacons3)}) off the world's robot 3 by at most {off:.3g} m")
    assert off < 1e-6  # (NaN, no beacon compared, fails too)
    assert s["collisions"] == 0 and s["min_agent_gap_m"] > 0 and s["agents_lost"] == []
    refused = refused_from(db, o.zid)
    assert refused.get("agent-3", {}).get("not_from_world", 0) == o.sent, refused  # each one, at its addressee


def test_forged_cmd_vel_cannot_move_a_robot(forged: tuple[dict, dict, Path]) -> None:
    s, outs, db = forged
    o = outs["cmd_vel"]
    assert o.sent > 100
    assert s["collisions"] == 0 and s["min_agent_gap_m"] > 0 and s["agents_lost"] == []
    refused = refused_from(db, o.zid)
    assert refused.get("simworld", {}).get("impersonation", 0) == o.sent, refused
    assert o.zid in s["intrusion_sources"]


def test_an_absurd_cmd_vel_crashes_nothing(tmp_path: Path) -> None:
    s, outs, _ = _run(tmp_path, ("absurd",))
    assert s["agents_lost"] == [] and s["collisions"] == 0
    assert s["messages_rejected_by_process"].get("simworld", 0) >= outs["absurd"].sent == 40  # refused at decode
    log = (tmp_path / "run" / "logs" / "agent-7.log").read_text()
    assert "OverflowError" not in log and "Traceback" not in log


def test_a_forged_token_cannot_hide_a_dead_agent(tmp_path: Path) -> None:
    s, outs, _ = _run(tmp_path, ("token",))
    assert s["agents_lost"] == [3] and s["collisions"] == 0, s
    late = [c for c in outs["token"].clocks if c.t >= KILL_AT_S + 6.0]  # the world drops it within its grace of silence
    assert late and all(3 not in c.alive for c in late), [c.alive for c in late[:3]]


@pytest.fixture(autouse=True)
def _paper_exists() -> None:
    assert PAPER.exists()
