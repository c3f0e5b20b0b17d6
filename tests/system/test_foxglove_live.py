"""The live view seen by a real WebSocket client: `run_local --foxglove PORT` serves the run while it records.

The client speaks the Foxglove WebSocket protocol by hand (the `websockets` package, subprotocol
`foxglove.sdk.v1`): it reads `serverInfo` and `advertise`, subscribes to every channel (`subscribe` op) and
decodes the binary `messageData` frames (opcode 1, uint32 subscription id, uint64 log time, payload) with
the schema each channel advertised (a protobuf FileDescriptorSet, or JSON), not with the project's code.
"""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import subprocess
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import websockets
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from websockets.typing import Subprotocol

from tests.support import PAPER, ROOT, free_port, launcher_cmd, short_paper, summary

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 1


@dataclass
class Watched:
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)  # topic -> advertised channel
    counts: dict[str, int] = field(default_factory=dict)
    first_s: dict[str, float] = field(default_factory=dict)
    last_s: dict[str, float] = field(default_factory=dict)
    log_ns: dict[str, list[int]] = field(default_factory=dict)
    last: dict[str, Any] = field(default_factory=dict)  # topic -> last decoded message
    server: dict[str, Any] = field(default_factory=dict)

    def rate_hz(self, topic: str) -> float:
        span = self.last_s.get(topic, 0.0) - self.first_s.get(topic, 0.0)
        return (self.counts.get(topic, 0) - 1) / span if span > 0 else 0.0


def _decoder(ch: dict[str, Any]) -> Any:
    if ch["encoding"] == "json":
        return lambda data: json.loads(data)
    assert ch["encoding"] == "protobuf" and ch.get("schemaEncoding", "protobuf") == "protobuf", ch
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))
    return cls.FromString


async def watch(port: int, seconds: float, connect_timeout_s: float = 60.0, until: Any = None) -> Watched:
    """Connect (retrying until the server is up), subscribe to every channel, collect for `seconds` (or until the
    server closes the connection, or the process `until` has ended)."""
    deadline = time.monotonic() + connect_timeout_s
    while True:
        try:
            ws = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[Subprotocol(SUBPROTOCOL)],
                                          max_size=None)
            break
        except OSError:
            if time.monotonic() > deadline or (until is not None and until.poll() is not None):
                raise
            await asyncio.sleep(0.2)
    w = Watched()
    subs: dict[int, str] = {}
    decoders: dict[str, Any] = {}
    async with ws:
        assert ws.subprotocol == SUBPROTOCOL
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0 and (until is None or until.poll() is None):
            try:
                msg = await asyncio.wait_for(ws.recv(), timeout=min(left, 1.0))
            except TimeoutError:
                continue
            except websockets.ConnectionClosed:
                break
            if isinstance(msg, str):
                op = json.loads(msg)
                if op["op"] == "serverInfo":
                    w.server = op
                elif op["op"] == "advertise":
                    new = []
                    for ch in op["channels"]:
                        sub_id = len(subs) + 1
                        subs[sub_id] = ch["topic"]
                        w.channels[ch["topic"]] = ch
                        decoders[ch["topic"]] = _decoder(ch)
                        new.append({"id": sub_id, "channelId": ch["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            opcode, sub_id, log_ns = struct.unpack_from("<BIQ", msg)
            assert opcode == MESSAGE_DATA, opcode
            topic = subs[sub_id]
            now = time.monotonic()
            w.counts[topic] = w.counts.get(topic, 0) + 1
            w.first_s.setdefault(topic, now)
            w.last_s[topic] = now
            w.log_ns.setdefault(topic, []).append(log_ns)
            w.last[topic] = decoders[topic](msg[13:])
    return w


@pytest.mark.realtime  # (the scene streams at 1-21 messages per wall second)
def test_live_view_serves_the_paper_mission(tmp_path: Path, out: Path) -> None:
    port = free_port()
    # The paper's first leg (tests.support.short_paper): the scene's channels and pace, not the paper's figures.
    cmd = launcher_cmd(out, "-s", str(short_paper(tmp_path)), "--foxglove", str(port), "--json")
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        w = asyncio.run(watch(port, seconds=20.0))
        stdout, stderr = proc.communicate(timeout=900)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, stderr[-2000:]
    run = json.loads(stdout)
    assert run["converged"] and run["collisions"] == 0

    assert w.server["op"] == "serverInfo"
    assert set(w.channels) == {"/world", "/swarm", "/tracking_error", "/metrics", "/events", "/knowledge"}
    assert w.channels["/swarm"]["schemaName"] == "foxglove.SceneUpdate"
    assert w.channels["/knowledge"]["schemaName"] == "foxglove.SceneUpdate"
    # the scene streams while the mission runs: at most 20 per wall second, and at least a few
    assert w.counts["/swarm"] >= 20, w.counts
    assert 1.0 <= w.rate_hz("/swarm") <= 21.0, w.rate_hz("/swarm")
    assert w.log_ns["/swarm"] == sorted(w.log_ns["/swarm"])
    scene = w.last["/swarm"]
    agents = {e.id: e for e in scene.entities if e.id.startswith("agent/")}
    assert set(agents) == {f"agent/{i}" for i in range(1, 11)}
    radii = {f"agent/{a['id']}": a["radius_m"] for a in _agents(PAPER)}
    for eid, e in agents.items():  # a disc of the agent's radius, in the mission's frame
        assert e.frame_id == "world"
        assert abs(e.cylinders[0].size.x - 2 * radii[eid]) < 1e-9
    # message time = the mission's wall-clock start + simulated time: close to now, not 1970
    assert abs(w.log_ns["/swarm"][-1] / 1e9 - time.time()) < 900
    err = w.last["/tracking_error"]
    assert {f"agent_{i}" for i in range(1, 11)} <= set(err)
    assert abs(err["max_m"] - max(err[f"agent_{i}"] for i in range(1, 11))) < 1e-9
    assert "/world" in w.counts and any(e.id == "slots" for e in w.last["/world"].entities)
    # what only the live swarm knows: every agent's known hulls (announced on its obstacle-set key)
    know = w.last["/knowledge"]
    assert {e.id for e in know.entities} <= {f"knowledge/{i}" for i in range(1, 11)}
    # the record is complete as without the live view
    s = summary(out / "run.db")
    assert s["converged"] and s["collisions"] == 0
    print(f"live view: channels {sorted(w.counts)}; messages {w.counts}; /swarm {w.rate_hz('/swarm'):.1f} Hz; "
          f"hulls known at the end of the watch: {sum(len(e.lines) for e in know.entities)}")


def _agents(path: Path) -> list[dict[str, Any]]:
    return list(tomllib.loads(path.read_text())["agents"])
