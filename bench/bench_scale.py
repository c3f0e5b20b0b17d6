#!/usr/bin/env python3
"""`reconswarm sim` at scale: a generated scenario (`reconswarm scenario generate --agents N --obstacles M`) cut to
a few simulated seconds, run by the command itself in a child process, one child per size. Per size it prints
the simulated time over the mission's wall time (>= 1: faster than real time), the mission loop's CPU time,
the child's CPU seconds and peak RSS (resource usage of the child, os.wait4), the record's size, and what
else ran (load averages, the busiest other processes): the machine may be shared.

    .venv/bin/python bench/bench_scale.py                          # 100,000 agents, 20 obstacles, 5 s simulated
    .venv/bin/python bench/bench_scale.py --agents 10000 100000 --seconds 5
    .venv/bin/python bench/bench_scale.py --agents 100000 --record-period 1
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, machine

ROOT = Path(__file__).resolve().parents[1]


def cli() -> list[str]:
    return [sys.executable, "-m", "reconswarm_bringup.cli"]


def others(me: int) -> str:
    """The busiest processes other than this benchmark's, by CPU share (ps)."""
    try:
        out = subprocess.run(["ps", "-eo", "pid,ppid,pcpu,comm", "--sort=-pcpu"], capture_output=True, text=True,
                             timeout=10).stdout.splitlines()[1:]
    except (OSError, subprocess.SubprocessError):
        return "n/a"
    busy = []
    for line in out:
        pid, ppid, pcpu, comm = line.split(None, 3)
        if int(pid) != me and int(ppid) != me and float(pcpu) >= 5.0:
            busy.append(f"{comm}({pcpu}%)")
    return ", ".join(busy[:8]) or "none over 5% CPU"


def scenario(n: int, obstacles: int, seed: int, seconds: float, tmp: Path) -> tuple[Path, float]:
    """Generate with the command, cut to `seconds` of simulated time. -> (file, generation wall s)"""
    full = tmp / f"gen-{n}.toml"
    t0 = time.perf_counter()
    subprocess.run([*cli(), "scenario", "generate", "--agents", str(n), "--obstacles", str(obstacles), "--seed",
                    str(seed), "-o", str(full)], check=True, cwd=ROOT)
    gen = time.perf_counter() - t0
    lines = full.read_text().splitlines(keepends=True)
    at = next(k for k, line in enumerate(lines) if line.startswith("duration_s = "))
    lines[at] = f"duration_s = {seconds!r}\n"
    cut = tmp / f"n{n}-{seconds:g}s.toml"
    cut.write_text("".join(lines))
    return cut, gen


def run_sim(path: Path, out: Path, record_period: float | None) -> tuple[dict[str, object], float, float, float]:
    """`reconswarm sim PATH --json` in a child. -> (summary, command wall s, child CPU s, child peak RSS MiB)"""
    args = [*cli(), "sim", str(path), "-o", str(out), "--json"]
    if record_period is not None:
        args += ["--record-period", repr(record_period)]
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as so:
        proc = subprocess.Popen(args, stdout=so, cwd=ROOT)
        _, status, use = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        so.seek(0)
        text = so.read().decode()
    if proc.returncode not in (0, 1):  # 1: the mission did not converge in the time given (expected)
        raise SystemExit(f"sim exited {proc.returncode}")
    return json.loads(text), wall, use.ru_utime + use.ru_stime, use.ru_maxrss / 1024


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents", type=int, nargs="+", default=[100_000], help="swarm sizes")
    ap.add_argument("--obstacles", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=5.0, help="simulated seconds (default 5)")
    ap.add_argument("--record-period", type=float, default=None, help="passed to sim (default: every tick)")
    args = ap.parse_args()
    every = "every tick" if args.record_period is None else f"every {args.record_period:g} s"
    print(f"# bench_scale: reconswarm sim, generated scenarios, {args.obstacles} obstacles, seed {args.seed}, "
          f"{args.seconds:g} s simulated, record {every}")
    print(f"# {machine()}")
    print(f"# reproduce: {command_line()}")
    print(f"{'agents':>7s} {'sim_s':>6s} {'mission_wall_s':>14s} {'sim/wall':>8s} {'mission_cpu_s':>13s} "
          f"{'sim/cpu':>7s} {'cmd_wall_s':>10s} {'cpu_s':>7s} {'peak_rss_MiB':>12s} {'run.db_MiB':>10s}  others")
    with tempfile.TemporaryDirectory(prefix="bench_scale_") as tmp:
        for n in args.agents:
            path, _ = scenario(n, args.obstacles, args.seed, args.seconds, Path(tmp))
            busy = others(os.getpid())
            summ, wall, cpu, rss = run_sim(path, Path(tmp) / f"run-{n}", args.record_period)
            sim_s = float(summ["duration_s"])  # type: ignore[arg-type]
            mwall = float(summ["wall_time_s"])  # type: ignore[arg-type]
            mcpu = float(summ.get("mission_cpu_s") or "nan")  # type: ignore[arg-type]
            db = (Path(tmp) / f"run-{n}" / "run.db").stat().st_size / 2**20
            print(f"{n:7d} {sim_s:6.2f} {mwall:14.2f} {sim_s / mwall:8.2f} {mcpu:13.2f} {sim_s / mcpu:7.2f} "
                  f"{wall:10.2f} {cpu:7.2f} {rss:12.0f} {db:10.1f}  {busy}")
            print(f"# after {n}: {machine()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
