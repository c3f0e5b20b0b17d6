#!/usr/bin/env python3
"""What the live view costs: the paper mission (lockstep, deploy/run_local.sh's launcher) with and without
`--foxglove`, alternating, with a WebSocket client subscribed to every channel for the whole of each
`--foxglove` run (tests/system/test_foxglove_live.watch: the subprotocol spoken by hand). Prints the
mission's wall time (summary `wall_time_s`, first clock to the end) per run and the medians, the monitor's
CPU seconds (its exit line), and what the client received.

    .venv/bin/python bench/bench_foxglove.py --pairs 3
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import asyncio
import contextlib
import json
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, machine, median

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from monitor.live import LiveView  # noqa: E402
from reconswarm.scenario.model import load  # noqa: E402
from tests.support import PAPER, free_port, launcher_cmd  # noqa: E402
from tests.system.test_foxglove_live import Watched, watch  # noqa: E402


def monitor_cpu_s(out: Path) -> float:
    m = re.search(r"'cpu_user_s': ([\d.]+), 'cpu_sys_s': ([\d.]+)", (out / "logs" / "monitor.log").read_text())
    return float(m.group(1)) + float(m.group(2)) if m else float("nan")


def one(out: Path, live: bool, tries: int = 3) -> tuple[dict[str, Any], float, Watched | None]:
    """One mission; a launch that could not start (exit 3: on a loaded machine the router may not answer in
    time) is tried again."""
    for attempt in range(tries):
        try:
            return _one(out, live)
        except StartFailed as exc:
            print(f"  (start failed, attempt {attempt + 1}: {exc})", flush=True)
    raise SystemExit("could not start the mission")


class StartFailed(Exception):
    pass


def _one(out: Path, live: bool) -> tuple[dict[str, Any], float, Watched | None]:
    port = free_port()
    args = ["-s", str(PAPER), "--json", *(["--foxglove", str(port)] if live else [])]
    proc = subprocess.Popen(launcher_cmd(out, *args), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    got: list[Watched] = []

    def client() -> None:
        with contextlib.suppress(OSError):  # the run never served (it failed to start)
            got.append(asyncio.run(watch(port, seconds=3600.0, connect_timeout_s=600.0, until=proc)))

    t = threading.Thread(target=client)
    if live:  # watch until the launcher is done (the server goes away with the monitor)
        t.start()
    stdout, stderr = proc.communicate(timeout=1800)
    if live:
        t.join(timeout=60)
    if proc.returncode == 3 and not stdout.strip():
        raise StartFailed(stderr.strip().splitlines()[-1][:200])
    if proc.returncode != 0:
        raise SystemExit(f"run failed (exit {proc.returncode}): {stderr[-1500:]}")
    return json.loads(stdout), monitor_cpu_s(out), (got[0] if got else None)


def tick_cost_ms(n: int = 400) -> tuple[float, float]:
    """(median ms per scene sent, ms per idle call) of LiveView.tick on the paper scenario, with and without a
    subscribed client (the idle call is what each recorded tick costs while nobody watches)."""
    s = load(PAPER)
    view = LiveView(s, 0, max_rate_hz=1e9)
    try:
        rng = np.random.default_rng(0)
        args = (np.ones(len(s.agents), dtype=bool), np.array([[0, 1], [1, 2]]), 1.0, 2.0, 3.0)
        t0 = time.perf_counter()
        for k in range(n):
            view.tick(float(k), k * 0.05, s.starts + rng.normal(size=s.starts.shape), s.headings, *args)
        idle_ms = (time.perf_counter() - t0) / n * 1e3
        box: list[Watched] = []
        th = threading.Thread(target=lambda: box.append(asyncio.run(watch(view.port, seconds=8.0))))
        th.start()
        while not view.listened():
            time.sleep(0.05)
        times = []
        for k in range(n):
            t0 = time.perf_counter()
            view.tick(float(k), k * 0.05, s.starts + rng.normal(size=s.starts.shape), s.headings, *args)
            times.append((time.perf_counter() - t0) * 1e3)
        th.join()
        return median(times), idle_ms
    finally:
        view.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=3)
    args = ap.parse_args()
    print(command_line())
    print(machine())
    sent_ms, idle_ms = tick_cost_ms()
    print(f"LiveView.tick, paper scenario (10 agents): {sent_ms:.3f} ms per scene sent to a subscribed client "
          f"(at most 20 per wall second: <= {20 * sent_ms / 10:.2f} % of a core), {idle_ms * 1e3:.1f} us per call "
          "with no client", flush=True)
    walls: dict[bool, list[float]] = {False: [], True: []}
    cpus: dict[bool, list[float]] = {False: [], True: []}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.pairs):
            for live in (i % 2 == 1, i % 2 == 0):  # alternate which goes first
                s, cpu, w = one(Path(tmp) / f"run{i}{int(live)}", live)
                walls[live].append(float(s["wall_time_s"]))
                cpus[live].append(cpu)
                extra = ""
                if w is not None:
                    extra = (f"; client: {sum(w.counts.values())} messages on {len(w.counts)} channels, /swarm "
                             f"{w.counts.get('/swarm', 0)} at {w.rate_hz('/swarm'):.1f} Hz")
                print(f"pair {i + 1} {'--foxglove' if live else 'plain     '}: converged {s['converged']} at "
                      f"{s['convergence_time_s']} s, contacts {s['collisions']}, wall {s['wall_time_s']:.1f} s, "
                      f"monitor CPU {cpu:.1f} s{extra}", flush=True)
    print(machine())
    for live in (False, True):
        print(f"{'--foxglove' if live else 'plain'}: wall median {median(walls[live]):.1f} s {walls[live]}, "
              f"monitor CPU median {median(cpus[live]):.1f} s")


if __name__ == "__main__":
    main()
