"""Open mode, attacked from an outside zenoh session with schema-correct messages (issue 11, "Open mode
trusts any local client"): forged commands for agent 2 steering it into agent 5, a phantom agent 99 of
radius 1e6 and a phantom with agent 4's id 60 m ahead, a 10 x 10,000 m hull and a 4,000-id obstacle set,
a clock ending the mission ("converged") and one switching to realtime, a second liveliness token for agent
3 (then agent 3 killed). The run must stay contact-free, record agent 3's loss, finish by itself, and count
every refused message as an intrusion with the attacker's session as the source.

What the attacker's session got refused is counted against what it sent, per receiving process and kind of
message: the world alone hears commands, so it must refuse every forged command; the monitor and every
agent hear every clock, so each must refuse every forged clock. One forgery let through is one missing
from its receiver's count (a takeover of agent 2's pin, say, lets the world take some commands).
"""

from __future__ import annotations

import json
import math
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import batch_to_wire
from reconswarm.net.wire.cells import CellGrid
from reconswarm.net.wire.hostwire import cmds_to_wire
from reconswarm.net.wire.keys import Keys
from reconswarm.plant.unicycle import inputs
from reconswarm.record.store import RunRecord
from reconswarm.scenario.model import load
from tests.support import (
    PAPER,
    ROOT,
    end_launch,
    events,
    free_port,
    launcher_cmd,
    read_run_id,
    wait_for_ticks,
    wait_until,
)

KILL_AT_S = 90.0


class Attacker:
    """An outside client on the run's router: follows the truth and the clock, sends forgeries."""

    def __init__(self, endpoint: str, run: str) -> None:
        self.z: Any = zenoh.open(ZenohOptions.build([endpoint], None, "client", None).config())
        self.zid = str(self.z.zid())
        self.keys = Keys(run)
        self.lock = threading.Lock()
        self.truth: wire.Truth | None = None
        self.clock: wire.Clock | None = None
        self.z.declare_subscriber(self.keys.truth, self._on_truth)
        self.z.declare_subscriber(self.keys.clock, self._on_clock)

    def _on_truth(self, s: Any) -> None:
        with self.lock:
            self.truth = wire.truth_from_wire(s.payload.to_bytes())

    def _on_clock(self, s: Any) -> None:
        c = wire.clock_from_wire(s.payload.to_bytes())
        with self.lock:
            if not c.end:
                self.clock = c

    def now(self) -> tuple[wire.Truth, wire.Clock]:
        def both() -> tuple[wire.Truth, wire.Clock] | None:
            with self.lock:
                return None if self.truth is None or self.clock is None else (self.truth, self.clock)

        return wait_until(both, 60.0, "the world's truth and clock heard")

    def put(self, key: str, payload: bytes) -> None:
        # BLOCK: a put under zenoh's default (DROP) may be dropped by our own session when its queue is full
        # (the 255 kB obstacle set just before the clocks): what was not sent cannot be counted as refused.
        self.z.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)

    def close(self) -> None:
        self.z.close()


def _attack(a: Attacker, until_t_s: float, timeout_s: float = 600.0) -> dict[str, int]:
    """Attack every 0.1 s of wall time until the run's clock passes until_t_s (simulated)."""
    s = load(PAPER)
    sent: dict[str, int] = {}

    def put(what: str, key: str, payload: bytes) -> None:
        a.put(key, payload)
        sent[what] = sent.get(what, 0) + 1

    token = a.z.liveliness().declare_token(a.keys.alive_agent(3))  # a second token for agent 3, kept
    oid = s.obstacles[0].id
    x0, y0 = (float(v) for v in s.polygon(0).mean(axis=0))
    Hull = tuple[tuple[float, float], ...]
    box: Hull = ((x0, y0 - 5.0), (x0 + 10_000.0, y0 - 5.0), (x0 + 10_000.0, y0 + 5.0), (x0, y0 + 5.0))
    tri: Hull = ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))
    slab = {oid: box}
    many = {f"o{i}": tri for i in range(4000)}
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        tr, c = a.now()
        if c.t > until_t_s:
            break
        idx = {aid: n for n, aid in enumerate(tr.ids)}
        p2 = (tr.px[idx[2]], tr.py[idx[2]])
        p5 = (tr.px[idx[5]], tr.py[idx[5]])
        d = math.hypot(p5[0] - p2[0], p5[1] - p2[1]) or 1.0
        u = np.array([[40.0 * (p5[0] - p2[0]) / d, 40.0 * (p5[1] - p2[1]) / d]])  # 40 m/s into agent 5
        v, w = inputs(u, np.array([tr.theta[idx[2]]]), s.head_offsets[[s.agent_index(2)]])  # as a command
        for k in (c.k, c.k + 1):
            put("cmd", a.keys.host(2, "cmd"), cmds_to_wire(2, [wire.Cmd(2, k, float(v[0]), float(w[0]))]))
        cx, cy = sum(tr.px) / len(tr.px), sum(tr.py) / len(tr.py)
        here = CellGrid.for_scenario(s).cell_of(cx, cy)  # the agents near the centroid listen to its cell
        # beacon batches as a host would put them: a phantom host 99, and one under agent 4's host key naming
        # agent 4 60 m ahead and the phantom (each row judged as a beacon)
        put("beacon", a.keys.host_beacons(here, 99), batch_to_wire(99, [wire.Beacon(99, c.k, c.t, cx, cy, 1e6)]))
        put("beacon", a.keys.host_beacons(here, 4), batch_to_wire(4, [wire.Beacon(4, c.k, c.t, cx + 60.0, cy, 2.6),
                                                                      wire.Beacon(99, c.k, c.t, cx, cy, 1e6)]))
        put("obstacles", a.keys.obstacles(here, 99), wire.obstacles_to_wire(wire.ObstacleSet(99, c.k, 1, slab)))
        put("obstacles", a.keys.obstacles(here, 4), wire.obstacles_to_wire(wire.ObstacleSet(4, c.k, 99, slab)))
        put("obstacles", a.keys.obstacles(here, 4), wire.obstacles_to_wire(wire.ObstacleSet(4, c.k, 98, many)))
        put("clock", a.keys.clock, wire.clock_to_wire(wire.Clock(c.k + 1, c.t + s.meta.dt_s, c.alive,
                                                                 end=True, reason="converged")))
        put("clock", a.keys.clock, wire.clock_to_wire(wire.Clock(c.k + 1, c.t + s.meta.dt_s, c.alive,
                                                                 mode=wire.ClockMode.REALTIME, speed=10.0)))
        time.sleep(0.1)
    token.undeclare()
    return sent


def test_outside_client_cannot_steer_phantom_end_or_hide_a_death(tmp_path: Path) -> None:
    out = tmp_path / "run"
    port = free_port()
    err = tmp_path / "launcher.err"
    with err.open("wb") as fh:
        proc = subprocess.Popen(launcher_cmd(out, "--json", "--fault", f"kill:agent:3@{KILL_AT_S:g}", port=port),
                                cwd=ROOT, stdout=subprocess.PIPE, stderr=fh)
    attacker: Attacker | None = None
    try:
        wait_for_ticks(out / "run.db", 20, proc, 180, lambda: err.read_text()[-2000:])
        attacker = Attacker(f"tcp/127.0.0.1:{port}", read_run_id(out))
        zid = attacker.zid
        sent = _attack(attacker, KILL_AT_S + 20.0)  # from t ~ 1 s to 20 s past agent 3's death
        stdout, _ = proc.communicate(timeout=900)
    finally:
        end_launch(proc, out, attacker)
    assert proc.returncode == 0, err.read_text()[-3000:]
    s = json.loads(stdout)
    print("sent:", sent, "summary:", {k: s[k] for k in ("converged", "convergence_time_s", "collisions",
                                                         "agents_lost", "intrusions", "intrusions_by_kind")})
    assert s["converged"] and s["collisions"] == 0 and s["agents_lost"] == [3]
    assert [e["kind"] for e in events(out / "run.db") if e.get("agent") == 3] == ["agent_lost"]
    assert s["duration_s"] > KILL_AT_S  # not ended by the spoofed clock
    by_kind = s["intrusions_by_kind"]
    for kind in ("impersonation", "unknown_agent", "not_from_world", "radius", "hull", "oversize"):
        assert by_kind.get(kind, 0) > 0, by_kind
    assert zid in s["intrusion_sources"]
    refused = refused_from(out / "run.db", zid)
    print("refused from the attacker's session, per process and kind:", refused)
    # Every forged command refused by the world, the only process that hears commands: as impersonation
    # (agent 2's session is pinned) or, for a tick not yet published, as a command (checked after the pin).
    world = refused.get("simworld", {})
    assert sum(world.values()) == sent["cmd"], (world, sent)
    assert set(world) <= {"impersonation", "command"}, world
    # Every forged clock refused by every process that hears the clock and ran throughout: the monitor and
    # the agents but agent 3 (killed meanwhile; its last tally may not have been reported).
    hearers = ["monitor"] + [f"agent-{a.id}" for a in load(PAPER).agents if a.id != 3]
    for process in hearers:
        got = refused.get(process, {})
        assert got.get("not_from_world", 0) == sent["clock"], (process, got, sent)


def refused_from(db: Path, source: str) -> dict[str, dict[str, int]]:
    """process -> kind -> how many of `source`'s messages it refused, from the run's record."""
    out: dict[str, dict[str, int]] = {}
    with RunRecord(db) as rec:
        rows = rec.intrusions()
    for row in rows:
        if row["source"] == source:
            kinds = out.setdefault(row["process"], {})
            kinds[row["kind"]] = kinds.get(row["kind"], 0) + int(row["count"])
    return out
