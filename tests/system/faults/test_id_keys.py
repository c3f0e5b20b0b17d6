"""Keys whose agent id is not the canonical decimal of one (issue 51, items 1 and 2), from an outside client on
the run's router during a short lockstep run of the paper mission (two agent hosts of five): a liveliness
token on `alive/agent/²` ('²'.isdigit(), but int('²') raises), one byte on `cell/<cell>/host/²/beacons` in
every cell an agent is in, on `host/²/cmd` and on `report/agent-²`; tokens on `alive/agent/03` and
`alive/agent/٣` (another key than agent 3's, read as agent 3 by a lax parser), and host tokens naming agents in
no canonical text (`alive/host/1/1-3,4-5`, `alive/host/03/3`), declared, held a few ticks and undeclared (a DELETE
that would say agent 3 left, or take its host's states away). Every process must survive them, the mission run its
course, and no agent be lost."""

from __future__ import annotations

import json
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.wire import wire
from reconswarm.net.wire.cells import CellGrid, cell_chunk
from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.model import load
from tests.support import (
    ROOT,
    end_launch,
    free_port,
    launcher_cmd,
    paper_with,
    read_run_id,
    tick_count,
    wait_for_ticks,
)

DURATION_S = 20.0
BAD_IDS = ("²", "03", "٣")  # a digit int() refuses, a leading zero, an Arabic-Indic 3
BAD_HOSTS = ("1/1-3,4-5", "03/3", "1/5,1-4")  # host 1's agents in no canonical text, host 3 with a leading zero


class Outsider:
    """An outside client on the run's router: follows the truth, puts and declares on keys of its choosing."""

    def __init__(self, endpoint: str, run: str) -> None:
        self.z: Any = zenoh.open(ZenohOptions.build([endpoint], None, "client", None).config())
        self.keys = Keys(run)
        self.lock = threading.Lock()
        self.truth: wire.Truth | None = None
        self.sub = self.z.declare_subscriber(self.keys.truth, self._on_truth)

    def _on_truth(self, s: Any) -> None:
        tr = wire.truth_from_wire(s.payload.to_bytes())
        with self.lock:
            self.truth = tr

    def newest(self, timeout_s: float = 60.0) -> wire.Truth:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self.lock:
                if self.truth is not None:
                    return self.truth
            time.sleep(0.05)
        raise AssertionError("no truth heard from the run")

    def put(self, key: str, payload: bytes) -> None:
        self.z.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)

    def close(self) -> None:
        self.z.close()


def _wait_ticks(db: Path, more: int, proc: subprocess.Popen[Any], timeout_s: float = 120.0) -> None:
    wait_for_ticks(db, tick_count(db) + more, proc, timeout_s, "the run stopped recording ticks")


def test_keys_with_unicode_digits_or_aliased_ids_kill_nobody_and_lose_no_agent(tmp_path: Path) -> None:
    out = tmp_path / "run"
    port = free_port()
    scenario = paper_with(tmp_path, **{"duration_s = 300.0": f"duration_s = {DURATION_S}"})
    err = tmp_path / "launcher.err"
    with err.open("wb") as fh:
        cmd = launcher_cmd(out, "-s", str(scenario), "--json", "--agents-per-process", "5", port=port)
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=fh)
    a: Outsider | None = None
    db = out / "run.db"
    try:
        wait_for_ticks(db, 20, proc, 180, lambda: err.read_text()[-2000:])
        a = Outsider(f"tcp/127.0.0.1:{port}", read_run_id(out))
        pre = a.keys.prefix
        grid = CellGrid.for_scenario(load(scenario))
        tr = a.newest()
        cells = {grid.cell_of(x, y) for x, y in zip(tr.px, tr.py, strict=True)}  # every agent hears its own cell
        a.put(f"{pre}/host/²/cmd", b"\x00")
        a.put(f"{pre}/report/agent-²", b"\x00")
        for c in cells:
            a.put(f"{pre}/cell/{cell_chunk(c)}/host/²/beacons", b"\x00")
        tokens = [a.z.liveliness().declare_token(f"{pre}/alive/agent/{bad}") for bad in BAD_IDS]
        tokens += [a.z.liveliness().declare_token(f"{pre}/alive/host/{bad}") for bad in BAD_HOSTS]
        _wait_ticks(db, 10, proc)
        for t in tokens:
            t.undeclare()  # (a DELETE on each key)
        _wait_ticks(db, 10, proc)
        stdout, _ = proc.communicate(timeout=300)
    finally:
        end_launch(proc, out, a)
    logs = {p.name: p.read_text(errors="replace") for p in (out / "logs").glob("*.log")}
    assert proc.returncode in (0, 1) and stdout.strip(), err.read_text()[-3000:]
    assert not [n for n, text in logs.items() if "Traceback" in text], {n: t[-1500:] for n, t in logs.items()
                                                                       if "Traceback" in t}
    s = json.loads(stdout)
    print("summary:", {k: s.get(k) for k in ("duration_s", "end_reason", "agents_lost", "collisions",
                                             "messages_rejected", "messages_rejected_by_process")})
    assert s["end_reason"] in ("duration", "converged") and s["agents_lost"] == [] and s["collisions"] == 0, s
    assert s["messages_rejected"] > 0, s  # the bad keys were counted as malformed
    assert not [ln for text in logs.values() for ln in text.splitlines() if "agent 3 is gone" in ln]
