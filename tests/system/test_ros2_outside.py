"""The ROS 2 face seen from outside, over a real router on 127.0.0.1: deploy/ros2_echo.py (a plain zenoh
session and rosbags, no project code) lists our liveliness tokens and decodes our odometry and attachments;
a Twist published the way a ROS 2 node does (rosbags CDR, attachment packed by hand) reaches our decoder."""

from __future__ import annotations

import json
import math
import queue
import struct
import subprocess
import sys
import time
from typing import Any

from rosbags.typesys import Stores, get_typestore

from reconswarm.net.ros2 import ros2
from reconswarm.net.ros2 import ros2_graph as graph
from reconswarm.net.runtime.session import ZenohOptions, open_session
from tests.support import ROOT, free_port

SAMPLES = 20


def _publish_until(
    echo: subprocess.Popen[str], s: Any, pubs: dict[int, ros2.Publication]
) -> dict[tuple[int, int], ros2.Odom]:
    """Publish both robots' odometry at 50 Hz until the echo tool has what it wants (samples sent before
    its subscription reached the router are lost, so keep publishing)."""
    sent: dict[tuple[int, int], ros2.Odom] = {}
    k = 0
    while echo.poll() is None and k < 1500:
        for i, pub in pubs.items():
            odom = ros2.Odom(i, 0.05 * k, 1.5 * i + 0.01 * k, -2.0 + 0.02 * k, 0.1 * k - 3.0, 0.3, -0.05 * i)
            sent[(i, k + 1)] = odom  # sequence numbers start at 1
            s.put(pub.key, ros2.odom_to_ros(odom), attachment=pub.next_attachment(time.time_ns()))
        k += 1
        time.sleep(0.02)
    return sent


def test_outside_tools_see_our_ros2_face(tmp_path):
    ep = f"tcp/127.0.0.1:{free_port()}"
    router = subprocess.Popen([sys.executable, "-m", "reconswarm_bringup.cli", "router", "--listen", ep], cwd=ROOT,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    sessions: list[Any] = []
    echo = None
    try:
        s = open_session(ZenohOptions.build([ep], None, "client", None), "test plant")
        sessions.append(s)
        zid = str(s.zid())
        node = graph.node_token(0, zid, 0, "simworld")
        pub_tokens = [graph.endpoint_token(graph.EntityKind.PUBLISHER, 0, zid, 0, 1 + i, "simworld",
                                           ros2.odom_topic(i), ros2.ODOMETRY, graph.QoS(depth=10)) for i in (0, 1)]
        declared = [s.liveliness().declare_token(k) for k in (node, *pub_tokens)]
        pubs = {i: ros2.Publication(ros2.odom_key(0, i)) for i in (0, 1)}
        echo = subprocess.Popen([sys.executable, str(ROOT / "deploy" / "ros2_echo.py"), "--connect", ep,
                                 "--count", str(SAMPLES), "--timeout", "60"], cwd=ROOT, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        sent = _publish_until(echo, s, pubs)
        out, err = echo.communicate(timeout=30)
        assert echo.returncode == 0, err
        lines = [json.loads(line) for line in out.splitlines()]

        # the graph as ROS 2 tools would build it: our node and both publishers, parsed back
        seen_tokens = {line["token"] for line in lines if "token" in line}
        assert {node, *pub_tokens} <= seen_tokens
        assert graph.parse_token(pub_tokens[1]).topic == graph.Topic(
            "/robot_1/odom", "nav_msgs::msg::dds_::Odometry_", ros2.type_hash(ros2.ODOMETRY), graph.QoS(depth=10))

        samples = [line for line in lines if "key" in line]
        assert len(samples) == SAMPLES
        last_seq: dict[str, int] = {}
        for smp in samples:
            i = ros2.agent_of_topic(ros2.parse_topic_key(smp["key"]).topic)
            assert smp["key"] == pubs[i].key and smp["gid"] == pubs[i].gid.hex()
            assert smp["seq"] > last_seq.get(smp["key"], 0)
            last_seq[smp["key"]] = smp["seq"]
            assert abs(smp["source_timestamp_ns"] / 1e9 - time.time()) < 120
            odom = sent[(i, smp["seq"])]
            assert (smp["frame_id"], smp["child_frame_id"]) == ("odom", f"robot_{i}/base_link")
            assert (smp["x"], smp["y"], smp["v"], smp["omega"]) == (odom.x_m, odom.y_m, odom.v_mps, odom.omega_radps)
            assert abs(smp["stamp_s"] - odom.t_s) < 1e-9
            assert abs(math.remainder(smp["yaw"] - odom.theta_rad, 2 * math.pi)) < 1e-9

        # the other direction: a Twist made by rosbags with a hand-packed attachment reaches our decoder
        inbox: queue.SimpleQueue[tuple[bytes, bytes]] = queue.SimpleQueue()
        s.declare_subscriber(ros2.cmd_vel_key(0, 1),
                             lambda smp: inbox.put((smp.payload.to_bytes(), smp.attachment.to_bytes())))
        outside = open_session(ZenohOptions.build([ep], None, "client", None), "test outside")
        sessions.append(outside)
        store: Any = get_typestore(Stores.ROS2_JAZZY)
        v3 = store.types["geometry_msgs/msg/Vector3"]
        twist = store.types["geometry_msgs/msg/Twist"](linear=v3(0.4, 0.0, 0.0), angular=v3(0.0, 0.0, -0.25))
        raw = bytes(store.serialize_cdr(twist, "geometry_msgs/msg/Twist", little_endian=True))
        key = "0/robot_1/cmd_vel/geometry_msgs::msg::dds_::Twist_/" + store.hash_rihs01("geometry_msgs/msg/Twist")
        gid = bytes(range(16))
        got = None
        for seq in range(1, 200):
            outside.put(key, raw, attachment=struct.pack("<qqB16s", seq, time.time_ns(), 16, gid))
            try:
                got = inbox.get(timeout=0.05)
                break
            except queue.Empty:
                continue
        assert got is not None, "no cmd_vel arrived"
        assert ros2.twist_from_ros(got[0]) == (0.4, -0.25)
        att = ros2.unpack_attachment(got[1])
        assert att.gid == gid and att.sequence_number >= 1
        for t in declared:
            t.undeclare()
    finally:
        if echo is not None and echo.poll() is None:
            echo.kill()
            echo.wait()
        for sess in sessions:
            sess.close()
        router.terminate()
        router.wait(timeout=10)
