#!/usr/bin/env python3
"""Watch the robots' ROS 2 odometry from outside the project, as `ros2 topic echo /robot_<i>/odom` would.

Only a plain zenoh session and rosbags (no reconswarm code): it lists the rmw_zenoh liveliness tokens of
the domain, subscribes to every `nav_msgs/msg/Odometry` topic of the domain, checks each sample's 33-byte
attachment and decodes its CDR payload with rosbags. One JSON object per line on stdout:
  {"token": "@ros2_lv/..."}     each liveliness token present when it starts
  {"ready": true}               subscribed
  {"key": ..., "seq": ..., "source_timestamp_ns": ..., "gid": hex, "stamp_s": ..., "frame_id": ...,
   "child_frame_id": ..., "x": ..., "y": ..., "yaw": ..., "v": ..., "omega": ...}
Exit 0 after --count samples, 1 if --timeout passes first, 2 on bad arguments.

  python deploy/ros2_echo.py --connect tcp/127.0.0.1:PORT [--domain 0] [--count 10] [--timeout 30]
"""

from __future__ import annotations

import argparse
import json
import math
import queue
import signal
import struct
import sys
import time
from typing import Any


def _project_python() -> None:
    """zenoh and rosbags missing from this Python: re-run in the project's .venv (deploy/setup_env.sh makes it), or
    say in one line how to get them (exit 2)."""
    import os
    from pathlib import Path

    venv = Path(__file__).resolve().parent.parent / ".venv"
    if (venv / "bin" / "python").exists() and Path(sys.prefix).resolve() != venv.resolve():
        os.execv(str(venv / "bin" / "python"), [str(venv / "bin" / "python"), __file__, *sys.argv[1:]])
    sys.stderr.write(f"ros2_echo.py: error: needs the Python packages eclipse-zenoh and rosbags, not in "
                     f"{sys.executable}: run deploy/setup_env.sh (or deploy/run_local.sh once) and then "
                     f"{venv}/bin/python deploy/ros2_echo.py, or pip install eclipse-zenoh rosbags\n")
    raise SystemExit(2)


try:
    import zenoh
    from rosbags.typesys import Stores, get_typestore
except ModuleNotFoundError:
    _project_python()
    raise

ODOMETRY = "nav_msgs/msg/Odometry"
ATTACHMENT = struct.Struct("<qqB16s")  # rmw_zenoh docs/design.md: seq, source timestamp, gid length, gid


def session(connect: str) -> Any:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([connect]))
    return zenoh.open(conf)


def decode(store: Any, key: str, payload: bytes, attachment: bytes | None) -> dict[str, Any]:
    if attachment is None or len(attachment) != ATTACHMENT.size:
        raise ValueError(f"attachment of {None if attachment is None else len(attachment)} bytes, expected 33")
    seq, ts_ns, gid_len, gid = ATTACHMENT.unpack(attachment)
    if gid_len != 16:
        raise ValueError(f"gid length {gid_len}, expected 16")
    msg = store.deserialize_cdr(payload, ODOMETRY)
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return {"key": key, "seq": seq, "source_timestamp_ns": ts_ns, "gid": gid.hex(),
            "stamp_s": msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, "frame_id": msg.header.frame_id,
            "child_frame_id": msg.child_frame_id, "x": p.x, "y": p.y, "yaw": yaw,
            "v": msg.twist.twist.linear.x, "omega": msg.twist.twist.angular.z}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--connect", required=True, help="router endpoint, e.g. tcp/127.0.0.1:7447")
    ap.add_argument("--domain", type=int, default=0, help="ROS 2 domain id")
    ap.add_argument("--count", type=int, default=0, help="exit after this many samples (0: run until stopped)")
    ap.add_argument("--timeout", type=float, default=0.0, help="exit 1 after this many seconds (0: never)")
    args = ap.parse_args()
    store = get_typestore(Stores.ROS2_JAZZY)
    inbox: queue.SimpleQueue[tuple[str, bytes, bytes | None]] = queue.SimpleQueue()
    stop: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: stop.append(signum))

    def on_sample(sample: Any) -> None:  # no zenoh calls, no blocking: hand over to the main loop
        att = sample.attachment
        inbox.put((str(sample.key_expr), sample.payload.to_bytes(), None if att is None else att.to_bytes()))

    s = session(args.connect)
    try:
        for reply in s.liveliness().get(f"@ros2_lv/{args.domain}/**", timeout=2.0):
            if reply.ok is not None:
                print(json.dumps({"token": str(reply.ok.key_expr)}), flush=True)
        sub = s.declare_subscriber(f"{args.domain}/**/nav_msgs::msg::dds_::Odometry_/*", on_sample)
        print(json.dumps({"ready": True}), flush=True)
        seen, deadline = 0, time.monotonic() + args.timeout if args.timeout > 0 else math.inf
        while not stop and (args.count == 0 or seen < args.count):
            if time.monotonic() > deadline:
                print(f"ros2_echo: timeout after {seen} samples", file=sys.stderr)
                return 1
            try:
                key, payload, att = inbox.get(timeout=0.1)
            except queue.Empty:
                continue
            try:
                print(json.dumps(decode(store, key, payload, att)), flush=True)
                seen += 1
            except Exception as exc:  # a foreign sample: say so, keep watching
                print(f"ros2_echo: undecodable sample on {key}: {exc}", file=sys.stderr)
        sub.undeclare()
        return 0
    finally:
        s.close()


if __name__ == "__main__":
    sys.exit(main())
