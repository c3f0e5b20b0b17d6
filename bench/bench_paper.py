#!/usr/bin/env python3
"""The paper scenario (Section V): mission wall time of `reconswarm sim` for both planners, convergence
times, and the benchmark-to-reconfigurable convergence ratio (paper: 241 s / 200 s ≈ 1.2).

Each repeat is a fresh `reconswarm sim deploy/scenarios/paper.toml --json` process, as a user runs it;
the figure is the summary's wall_time_s (the mission loop, recording included), median of the repeats.
cpu_s is the whole process's CPU time (start-up and imports included): on a busy machine it shows
what wall time cannot.

    .venv/bin/python bench/bench_paper.py            # 5 repeats per planner
    .venv/bin/python bench/bench_paper.py --quick    # 1 repeat per planner
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, fmt_list, machine, median

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "deploy" / "scenarios" / "paper.toml"
PLANNERS = ("reconfigurable", "virtual-leader")
PAPER_S = {"reconfigurable": 200.0, "virtual-leader": 241.0}


def sim(planner: str, out: Path) -> tuple[dict[str, Any], float]:
    """One `reconswarm sim` process: its summary and its CPU time (user + system, start-up included)."""
    cmd = [sys.executable, "-m", "reconswarm_bringup.cli", "sim", str(SCENARIO), "--planner", planner, "-o", str(out),
           "--json"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):
        raise SystemExit(f"bench_paper: {' '.join(cmd)} failed ({done.returncode}): {done.stderr.strip()}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return json.loads(done.stdout), cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5, help="runs per planner (default 5)")
    ap.add_argument("--quick", action="store_true", help="smoke run: 1 repeat per planner")
    args = ap.parse_args()
    repeats = 1 if args.quick else max(1, args.repeats)
    print(f"# bench_paper: {SCENARIO.relative_to(ROOT)}, {repeats} run(s) per planner, fresh process each")
    print(f"# {machine()}")
    print(f"# reproduce: {command_line()}")
    conv: dict[str, float | None] = {}
    print(f"{'planner':16s} {'wall_s median':>13s} {'cpu_s median':>12s} {'ticks':>6s} {'converged_s':>11s} "
          f"{'paper_s':>7s} {'collisions':>10s}  wall_s runs")
    with tempfile.TemporaryDirectory(prefix="bench_paper_") as tmp:
        for planner in PLANNERS:
            walls, cpus, summaries = [], [], []
            for r in range(repeats):
                summary, cpu = sim(planner, Path(tmp) / f"{planner}-{r}")
                walls.append(float(summary["wall_time_s"]))
                cpus.append(cpu)
                summaries.append(summary)
            last = summaries[-1]
            times = {s["convergence_time_s"] for s in summaries}
            if len(times) != 1:
                print(f"warning: {planner}: convergence time differs between runs: {sorted(map(str, times))}")
            conv[planner] = last["convergence_time_s"]
            shown = "-" if conv[planner] is None else f"{conv[planner]:.2f}"
            print(f"{planner:16s} {median(walls):13.3f} {median(cpus):12.2f} {last.get('ticks', '?'):>6} "
                  f"{shown:>11s} {PAPER_S[planner]:7.1f} {last['collisions']:10d}  {fmt_list(walls)}")
    rc, vl = conv["reconfigurable"], conv["virtual-leader"]
    if rc and vl:
        print(f"convergence ratio virtual-leader / reconfigurable: {vl / rc:.3f} "
              f"({vl:.2f} s / {rc:.2f} s; paper {PAPER_S['virtual-leader'] / PAPER_S['reconfigurable']:.3f} "
              f"= 241 s / 200 s)")
    else:
        print("convergence ratio: n/a (a planner did not converge)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
