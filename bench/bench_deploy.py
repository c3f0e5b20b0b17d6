"""The distributed deployment, measured with real processes through deploy/run_local.sh's launcher:

1. lockstep: simulated seconds per wall second for N = 10, 25, 50 agent processes (generated scenarios,
   run for a fixed simulated time);
2. realtime at --speed 1 (the control loop at 1/dt = 20 Hz): the largest N whose missed-deadline ratio
   stays below 1 %, trying N in increasing order;
3. memory per process (peak RSS, from each process's exit line in its log), median per role;
4. state-to-command latency p50/p99 in realtime beside a raw zenoh round trip (put -> echo -> reply)
   measured through the same router during the same run.

    .venv/bin/python bench/bench_deploy.py            # all four
    .venv/bin/python bench/bench_deploy.py --quick    # N = 10 only, short runs
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, machine, median

from reconswarm.generate import generate
from reconswarm.scenario import to_toml

ROOT = Path(__file__).resolve().parent.parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def scenario(tmp: Path, n: int, sim_s: float, seed: int = 1) -> Path:
    s = generate(n, 3, seed)
    s = dataclasses.replace(s, meta=dataclasses.replace(s.meta, duration_s=sim_s))
    path = tmp / f"n{n}.toml"
    path.write_text(to_toml(s))
    return path


def launch(out: Path, scen: Path, port: int, *extra: str, timeout: float = 1800) -> dict:
    p = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli_launch", "--router", f"tcp/127.0.0.1:{port}",
                        "-o", str(out), "-s", str(scen), "--no-progress", "--json", *extra], capture_output=True,
                       text=True, timeout=timeout, cwd=ROOT)
    if p.returncode not in (0, 1):
        raise RuntimeError(f"run failed ({p.returncode}): {p.stderr[-1500:]}")
    return json.loads(p.stdout)


def rss_by_role(out: Path) -> dict[str, list[float]]:
    roles: dict[str, list[float]] = {}
    for log in (out / "logs").glob("*.log"):
        m = re.findall(r"usage: \{.*'max_rss_mb': ([0-9.]+)\}", log.read_text(errors="replace"))
        if m:
            roles.setdefault(log.stem.split("-")[0], []).append(float(m[-1]))
    return roles


def zenoh_rtt(port: int, stop: threading.Event, samples: list[float]) -> None:
    """Round trips through the run's router: ping on one session, echo on another."""
    import zenoh

    from reconswarm.net.session import ZenohOptions, open_session

    opts = ZenohOptions.build([f"tcp/127.0.0.1:{port}"], None, "client", None)
    time.sleep(3.0)  # let the run start
    a, b = open_session(opts, "bench ping"), open_session(opts, "bench echo")
    got = threading.Event()
    try:
        echo_pub = b.declare_publisher("bench/rtt/pong", congestion_control=zenoh.CongestionControl.BLOCK)
        b.declare_subscriber("bench/rtt/ping", lambda s: echo_pub.put(s.payload.to_bytes()))
        a.declare_subscriber("bench/rtt/pong", lambda s: got.set())
        ping = a.declare_publisher("bench/rtt/ping", congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(0.5)
        while not stop.is_set():
            got.clear()
            t0 = time.perf_counter()
            ping.put(b"x" * 64)
            if got.wait(1.0):
                samples.append((time.perf_counter() - t0) * 1000.0)
            time.sleep(0.02)
    finally:
        a.close()
        b.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lockstep-agents", type=int, nargs="+", default=[10, 25, 50])
    ap.add_argument("--lockstep-sim-s", type=float, default=30.0, help="simulated seconds per lockstep run")
    ap.add_argument("--realtime-agents", type=int, nargs="+", default=[5, 10, 20, 30, 40, 50, 60])
    ap.add_argument("--realtime-sim-s", type=float, default=20.0, help="simulated (= wall) seconds per run")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.lockstep_agents, args.lockstep_sim_s, args.realtime_agents, args.realtime_sim_s = [10], 10.0, [5], 8.0
    print("# bench_deploy: real processes (router, simworld, monitor, N agents) on 127.0.0.1")
    print(f"# {machine()}")
    print(f"# reproduce: {command_line()}")
    with tempfile.TemporaryDirectory(prefix="bench_deploy_") as t:
        tmp = Path(t)
        print(f"\n## lockstep: {args.lockstep_sim_s:g} s simulated per run (generated scenarios, 3 obstacles)")
        print(f"{'agents':>6s} {'processes':>9s} {'wall_s':>8s} {'sim/wall':>9s}  peak RSS MB median by role")
        for n in args.lockstep_agents:
            out = tmp / f"lock{n}"
            s = launch(out, scenario(tmp, n, args.lockstep_sim_s), free_port())
            rss = {r: round(median(v), 1) for r, v in sorted(rss_by_role(out).items())}
            wall = s["wall_time_s"]
            print(f"{n:6d} {n + 3:9d} {wall:8.2f} {s['duration_s'] / wall:9.2f}  {rss}")
        print(f"\n## realtime at --speed 1 (control rate 20 Hz), {args.realtime_sim_s:g} s per run")
        print(f"{'agents':>6s} {'missed':>7s} {'ratio':>7s} {'lat p50 ms':>10s} {'lat p99 ms':>10s} "
              f"{'zenoh rtt p50':>13s} {'rtt p99':>8s}")
        best = 0
        for n in args.realtime_agents:
            out = tmp / f"rt{n}"
            port = free_port()
            stop, rtt = threading.Event(), list[float]()
            th = threading.Thread(target=zenoh_rtt, args=(port, stop, rtt), daemon=True)
            th.start()
            try:
                s = launch(out, scenario(tmp, n, args.realtime_sim_s), port, "--clock", "realtime", "--speed", "1")
            finally:
                stop.set()
                th.join(timeout=5)
            ratio = s.get("missed_deadline_ratio", float("nan"))
            r50 = statistics.median(rtt) if rtt else float("nan")
            r99 = sorted(rtt)[int(0.99 * (len(rtt) - 1))] if rtt else float("nan")
            print(f"{n:6d} {int(s.get('missed_deadlines', -1)):7d} {ratio:7.2%} {s.get('latency_p50_ms', 0):10.2f} "
                  f"{s.get('latency_p99_ms', 0):10.2f} {r50:13.2f} {r99:8.2f}")
            if ratio < 0.01:
                best = n
            else:
                break
        print(f"\nlargest N holding 20 Hz with < 1 % missed deadlines: {best if best else 'none of those tried'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
