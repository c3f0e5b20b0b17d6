"""Issue 12: every event the monitor records is published on `swarm/<run>/event`, exactly once, as recorded.

An outside subscriber (a plain zenoh-python session in its own process: docs/wire.md's example, nothing of
reconswarm imported) follows a whole paper mission through the run's router and writes what it heard;
that list must equal `reconswarm monitor events --json` (same events, same order, same fields)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.support import ROOT, events, free_port, launcher_cmd

pytestmark = pytest.mark.system

FOLLOW = """
import json, signal, sys, threading, msgpack, zenoh
conf = zenoh.Config.from_json5(
    '{mode: "client", connect: {endpoints: ["%s"]}, scouting: {multicast: {enabled: false}}}')
heard, done = [], threading.Event()
signal.signal(signal.SIGTERM, lambda *_: done.set())
with zenoh.open(conf) as z:
    sub = z.declare_subscriber("swarm/*/event",
                               lambda s: heard.append([str(s.key_expr), msgpack.unpackb(s.payload.to_bytes())]))
    print("subscribed", flush=True)
    done.wait()
json.dump(heard, sys.stdout)
"""


def test_outside_subscriber_hears_every_recorded_event(tmp_path: Path, out: Path) -> None:
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen([sys.executable, "-m", "reconswarm_bringup.cli", "router", "--listen", ep], cwd=ROOT,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    follower = None
    try:
        time.sleep(1.0)
        follower = subprocess.Popen([sys.executable, "-c", FOLLOW % ep], stdout=subprocess.PIPE, text=True, cwd=ROOT)
        assert follower.stdout is not None
        assert follower.stdout.readline().strip() == "subscribed"
        cmd = launcher_cmd(out, "--json", port=port)
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=900, cwd=ROOT)
        assert p.returncode == 0, p.stderr[-3000:]
        time.sleep(0.5)
        follower.send_signal(signal.SIGTERM)
        heard_text, _ = follower.communicate(timeout=10)
    finally:
        for proc in (follower, router):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    run_id = (out / "run_id").read_text().strip()  # the launch's own run id (unique per launch)
    keys = {key for key, _ in json.loads(heard_text)}
    assert keys <= {f"swarm/{run_id}/event"}, keys
    heard = [e for _, e in json.loads(heard_text)]
    assert all(e.pop("v") == 1 for e in heard)
    recorded = events(out / "run.db")
    (tmp_path / "events_wire_vs_record.json").write_text(json.dumps({"wire": heard, "record": recorded}, indent=1))
    assert len(recorded) >= 4 and {e["kind"] for e in recorded} >= {"split", "merge"}
    assert heard == recorded
