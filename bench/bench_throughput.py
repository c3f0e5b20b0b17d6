#!/usr/bin/env python3
"""In-process engine throughput: agent-steps per second (N * ticks / wall) at N = 100, 500, 1000 agents,
10 obstacles, generated scenarios (`reconswarm scenario generate --agents N --obstacles 10 --seed S`),
each run for a fixed number of steps so the benchmark is bounded in time. Wall is the summary's
wall_time_s (the mission loop with run.db recording); the figure is the median over the repeats.

    .venv/bin/python bench/bench_throughput.py                  # 600 steps, 3 repeats, N = 100 500 1000
    .venv/bin/python bench/bench_throughput.py --quick          # 60 steps, 1 repeat
    .venv/bin/python bench/bench_throughput.py --agents 500 --ticks 1500
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, fmt_list, machine, median, with_ticks

from reconswarm.scenario.generate import generate
from reconswarm_bringup import engine


def run_once(n: int, obstacles: int, seed: int, ticks: int, out: Path) -> tuple[int, float, float]:
    """-> (ticks run, mission wall s, process CPU s over the run)"""
    s = with_ticks(generate(n, obstacles, seed), ticks)
    cpu0 = time.process_time()
    summary = engine.run(engine.SimConfig(s, out, progress=False))
    cpu = time.process_time() - cpu0
    return int(summary["ticks"]), float(summary["wall_time_s"]), cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents", type=int, nargs="+", default=[100, 500, 1000], help="swarm sizes")
    ap.add_argument("--obstacles", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--ticks", type=int, default=600, help="steps per run (default 600 = 30 s simulated)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="smoke run: 60 steps, 1 repeat")
    args = ap.parse_args()
    ticks, repeats = (60, 1) if args.quick else (args.ticks, max(1, args.repeats))
    print(f"# bench_throughput: generated scenarios, {args.obstacles} obstacles, seed {args.seed}, "
          f"{ticks} steps, {repeats} repeat(s), in-process engine with run.db recording")
    print(f"# {machine()}")
    print(f"# reproduce: {command_line()}")
    print(f"{'agents':>6s} {'ticks':>6s} {'agent-steps/s median':>20s} {'wall_s median':>13s} "
          f"{'agent-steps/cpu-s':>17s}  wall_s runs")
    with tempfile.TemporaryDirectory(prefix="bench_throughput_") as tmp:
        for n in args.agents:
            walls, cpus, done = [], [], 0
            for r in range(repeats):
                done, wall, cpu = run_once(n, args.obstacles, args.seed, ticks, Path(tmp) / f"n{n}-{r}")
                walls.append(wall)
                cpus.append(cpu)
            wall = median(walls)
            print(f"{n:6d} {done:6d} {n * done / wall:20,.0f} {wall:13.3f} {n * done / median(cpus):17,.0f}  "
                  f"{fmt_list(walls)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
