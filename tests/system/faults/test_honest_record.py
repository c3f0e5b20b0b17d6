"""Open mode cannot authenticate, but its record must not lie (issue 20). An outside client on the run's
router overhears agent 2's and the world's session ids and stamps them on its own messages: commands for
agent 2 (each tick's, with another (v, ω)), one clock ending the mission as "converged" at t ~ 3 s; it also
sends clocks from its own session (every process hears each) and holds a liveliness token for agent 3, which
the launcher kills. The paper mission, cut to DURATION_S, lockstep, on a router at 127.0.0.1:

- the conflicting commands make the run not deterministic, as intrusions;
- the forged end is refused (the agents and the monitor go on; an 'end' intrusion) and the record ends where
  the world ended it, never 'converged' next to converged: false;
- the world does not wait for dead agent 3 through its strikes because of the token;
- a forged clock heard by the monitor and every agent is one intrusion, not eleven.
"""

from __future__ import annotations

import datetime
import json
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.wire import wire
from reconswarm.net.wire.hostwire import cmds_to_wire
from reconswarm.net.wire.keys import Keys
from tests.support import (
    ROOT,
    end_launch,
    free_port,
    launcher_cmd,
    paper_with,
    read_run_id,
    wait_for_ticks,
    wait_until,
)

DURATION_S = 20.0
KILL_AT_S = 8.0


class Stamper:
    """An outside client that learns session ids from what it overhears and stamps them on its puts."""

    def __init__(self, endpoint: str, run: str) -> None:
        self.z: Any = zenoh.open(ZenohOptions.build([endpoint], None, "client", None).config())
        self.keys = Keys(run)
        self.lock = threading.Lock()
        self.ids: dict[str, Any] = {}  # "world" | "agent 2" -> the ZenohId its samples carry
        self.clock: wire.Clock | None = None
        self.subs = [self.z.declare_subscriber(self.keys.clock, self._on_clock, allowed_origin=zenoh.Locality.REMOTE),
                     self.z.declare_subscriber(self.keys.host(2, "cmd"), self._on_cmd)]

    def _on_clock(self, s: Any) -> None:
        c = wire.clock_from_wire(s.payload.to_bytes())
        with self.lock:
            if s.timestamp is not None and "world" not in self.ids and not c.end:
                self.ids["world"] = s.timestamp.get_id()
            if not c.end:
                self.clock = c

    def _on_cmd(self, s: Any) -> None:
        with self.lock:
            if s.timestamp is not None:
                self.ids.setdefault("agent 2", s.timestamp.get_id())

    def ready(self) -> tuple[wire.Clock, Any, Any]:
        def heard() -> tuple[wire.Clock, Any, Any] | None:
            with self.lock:
                if self.clock is not None and {"world", "agent 2"} <= set(self.ids):
                    return self.clock, self.ids["world"], self.ids["agent 2"]
                return None

        return wait_until(heard, 60.0, "the clock and the ids of the world and of agent 2", every_s=0.02)

    def put_as(self, zid: Any, key: str, payload: bytes) -> None:
        self.z.put(key, payload, timestamp=zenoh.Timestamp(datetime.datetime.now(datetime.UTC), zid),
                   congestion_control=zenoh.CongestionControl.BLOCK)  # (DROP could lose what we count as sent)

    def close(self) -> None:
        self.z.close()


def test_the_record_does_not_lie_about_commands_ends_or_the_dead(tmp_path: Path) -> None:
    out = tmp_path / "run"
    port = free_port()
    scenario = paper_with(tmp_path, **{"duration_s = 300.0": f"duration_s = {DURATION_S}"})
    err = tmp_path / "launcher.err"
    with err.open("wb") as fh:
        cmd = launcher_cmd(out, "-s", str(scenario), "--json", "--fault", f"kill:agent:3@{KILL_AT_S:g}", port=port)
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=fh)
    a: Stamper | None = None
    sent = {"cmd": 0, "clock": 0, "end": 0}
    try:
        wait_for_ticks(out / "run.db", 20, proc, 120, lambda: err.read_text()[-2000:])
        a = Stamper(f"tcp/127.0.0.1:{port}", read_run_id(out))
        token = a.z.liveliness().declare_token(a.keys.alive_agent(3))  # held for agent 3 (killed at KILL_AT_S)
        dt = 0.05
        while proc.poll() is None:
            c, world, agent2 = a.ready()
            if c.t > DURATION_S - 2.0:
                break
            # not agent 2's command (agent 2 is a host of one: its commands go under host 2's key)
            a.put_as(agent2, a.keys.host(2, "cmd"), cmds_to_wire(2, [wire.Cmd(2, c.k, -0.7, 0.3)]))
            sent["cmd"] += 1
            a.z.put(a.keys.clock, wire.clock_to_wire(wire.Clock(c.k + 1, c.t + dt, c.alive)),  # our own session's
                    congestion_control=zenoh.CongestionControl.BLOCK)
            sent["clock"] += 1
            if sent["end"] == 0 and c.t >= 3.0:
                a.put_as(world, a.keys.clock, wire.clock_to_wire(wire.Clock(c.k + 1, c.t + dt, c.alive, end=True,
                                                                            reason="converged")))
                sent["end"] += 1
            time.sleep(0.05)
        token.undeclare()
        stdout, _ = proc.communicate(timeout=300)
    finally:
        end_launch(proc, out, a)
    assert proc.returncode in (0, 1) and stdout.strip(), err.read_text()[-3000:]
    s = json.loads(stdout)
    print("sent:", sent, "summary:", {k: s.get(k) for k in (
        "duration_s", "end_reason", "converged", "collisions", "agents_lost", "deterministic", "determinism_lost_at_s",
        "intrusions", "intrusions_by_kind", "intrusions_by_process")})
    assert sent["end"] == 1 and sent["cmd"] > 10
    # the record's end is the world's, and it agrees with the truth
    assert not (s.get("end_reason") == "converged" and not s["converged"]), s
    assert s["end_reason"] == "duration" and s["duration_s"] >= DURATION_S - 0.1, s
    assert s["intrusions_by_kind"].get("end", 0) >= 1
    # two commands for agent 2's ticks: not deterministic, and said
    assert s["deterministic"] is False and s["determinism_lost_at_s"] is not None
    assert s["intrusions_by_kind"].get("conflicting_command", 0) >= 1
    # the dead agent is lost, and the world did not wait for it through its strikes
    assert s["agents_lost"] == [3] and s["collisions"] == 0
    world_log = (out / "logs" / "simworld.log").read_text()
    assert "unresponsive" not in world_log and "no command from [3]" not in world_log, world_log[-2000:]
    # each forged clock from our own session is one intrusion, though the monitor and every agent refused it
    assert s["intrusions_by_kind"].get("not_from_world") == sent["clock"], s["intrusions_by_kind"]
    assert s["intrusions_by_process"]["monitor"] >= sent["clock"]
