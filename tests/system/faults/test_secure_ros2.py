"""`run_local.sh --secure --ros2 --foxglove PORT`: the ROS 2 keys and the live view under the access rules.

One short run of the paper mission (cut to DURATION_S, real time): the plant's odometry and the agents'
cmd_vel flow (no agent is lost: the world counts an agent alive by its token AND its cmd_vel), the live view
shows what the swarm knows (the agents' obstacle sets, which the monitor may now read); an outside session
without credentials cannot open, and a certificate of the run's CA that no rule names hears nothing (no
odometry, no cmd_vel, no rmw_zenoh liveliness token) and says nothing: its forged cmd_vel for robot 3 and
odometry for robot 5 reach no process (0 intrusions counted, where open mode counts each as impersonation).
"""

from __future__ import annotations

import asyncio
import json
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest

from reconswarm.net.ros2 import ros2
from tests.support import (
    ROOT,
    assert_all_gone,
    free_port,
    launcher_cmd,
    paper_with,
    read_run_id,
    wait_for_ticks,
)
from tests.system.test_foxglove_live import watch

from .test_secure import Catch, _anonymous_config, _open

pytestmark = pytest.mark.realtime  # (holds only if the machine keeps the clock's pace: run alone, last)

DOMAIN = 13
DURATION_S = 30.0


def test_secure_ros2_and_live_view(tmp_path: Path) -> None:
    import zenoh

    out, port, view = tmp_path / "run", free_port(), free_port()
    scen = paper_with(tmp_path, **{"duration_s = 300.0": f"duration_s = {DURATION_S}"})
    err = tmp_path / "launcher.err"
    with err.open("wb") as fh:
        proc = subprocess.Popen(launcher_cmd(out, "-s", str(scen), "--secure", "--ros2", "--ros-domain-id",
                                             str(DOMAIN), "--foxglove", str(view), "--json", port=port),
                                cwd=ROOT, stdout=subprocess.PIPE, stderr=fh)
    seen = {"hulls": 0, "swarm": 0}  # the most hulls one /knowledge scene drew, /swarm scenes in all

    def view_it() -> None:
        """Short watches one after another (a watch keeps the last scene of each channel) until the run ends."""
        while proc.poll() is None:
            try:
                w = asyncio.run(watch(view, seconds=3.0, until=proc))
            except OSError:
                continue
            know = w.last.get("/knowledge")
            seen["hulls"] = max(seen["hulls"], sum(len(e.lines) for e in know.entities) if know is not None else 0)
            seen["swarm"] += w.counts.get("/swarm", 0)

    viewer = threading.Thread(target=view_it, daemon=True)
    viewer.start()
    try:
        wait_for_ticks(out / "run.db", 20, proc, 300, lambda: err.read_text()[-3000:])
        run = f"swarm/{read_run_id(out)}"
        outcome = {}
        for what, ep in (("tls", f"tls/127.0.0.1:{port}"), ("tcp", f"tcp/127.0.0.1:{port}")):
            try:
                zenoh.open(_anonymous_config(ep)).close()
                outcome[what] = "opened"
            except Exception as exc:
                outcome[what] = f"refused: {exc}".splitlines()[0][:100]
        # the intruder's certificate in two sessions: one listens, one forges (a session hears its own puts)
        cert = out / "secrets" / "intruder.json5"
        intruder, forger, heard = _open(cert), _open(cert), Catch()
        intruder.declare_subscriber(f"{DOMAIN}/**", heard)
        intruder.declare_subscriber(f"{run}/**", heard)
        intruder.liveliness().declare_subscriber("@ros2_lv/**", heard, history=True)
        time.sleep(2.0)
        cmd3, odom5 = ros2.Publication(ros2.cmd_vel_key(DOMAIN, 3)), ros2.Publication(ros2.odom_key(DOMAIN, 5))
        forged = 0
        for _ in range(100):
            forger.put(cmd3.key, ros2.twist_to_ros(1.5, 0.0), attachment=cmd3.next_attachment(time.time_ns()))
            forger.put(odom5.key, ros2.odom_to_ros(ros2.Odom(5, 1.0, 40.0, 40.0, 0.0, 0.0, 0.0)),
                         attachment=odom5.next_attachment(time.time_ns()))
            forged += 2
            time.sleep(0.02)
        time.sleep(2.0)
        tokens = list(intruder.liveliness().get("@ros2_lv/**", timeout=2.0))
        intruder.close()
        forger.close()
        stdout, _ = proc.communicate(timeout=300)
        viewer.join(timeout=60)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
        assert_all_gone(out)
    assert proc.returncode in (0, 1), err.read_text()[-3000:]  # (1: not converged in the cut mission)
    s = json.loads(stdout)
    print(f"secure ROS 2 + live view: {s['ticks']} ticks, collisions {s['collisions']}, lost {s['agents_lost']}, "
          f"intrusions {s['intrusions']}, path {s['path_length_m']}; outsiders {outcome}; intruder heard "
          f"{len(heard)} samples and {sum(1 for r in tokens if r.ok is not None)} tokens after {forged} forgeries; "
          f"live view: at most {seen['hulls']} hulls in a /knowledge scene, {seen['swarm']} /swarm scenes")
    assert all(o.startswith("refused") for o in outcome.values()), outcome
    assert len(heard) == 0 and not any(r.ok is not None for r in tokens)
    assert s["collisions"] == 0 and s["agents_lost"] == [] and s["intrusions"] == 0, s
    assert s["finished"] and s["messages_rejected"] == 0
    # the robots moved (odometry and cmd_vel flowed through the rules), robot 5 not to (40, 40)
    assert min(s["path_length_m"].values()) > 1.0 if isinstance(s["path_length_m"], dict) else s["path_length_m"] > 1
    # the live view drew what the agents know: the monitor reads their obstacle sets
    assert seen["hulls"] > 0 and seen["swarm"] >= 20, seen
