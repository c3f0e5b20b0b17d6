#!/usr/bin/env python3
"""Success rate over generated scenarios with obstacles: a run succeeds when it converges (every
|e_i| <= tol) with zero collisions. Prints, per suite and size, the success rate, the convergence time
(median and p90 over the converged runs), the contact count (collision episodes, and safety-band
episodes beside), and every failing seed with its reason.

Two suites (`--suite small|large|all`, default all):
- small: seed s (0..49) uses N = 10 + (13 s mod 21) agents (10..30) and M = 4 + (floor(s / 2) mod 3)
  obstacles (4..6);
- large: N = 50, 100 and 200 agents with M = 8 obstacles, seeds 0..9 each.
Each run is `reconswarm scenario generate --agents N --obstacles M --seed s` run to its own duration with
the in-process engine, through the sweep runner (`reconswarm_bringup.sweep.run_sweep`) on a ProcessPoolExecutor
(`--workers`, default 2, spawn context).

    .venv/bin/python bench/bench_success.py                    # both suites (N = 200 runs take minutes)
    .venv/bin/python bench/bench_success.py --suite large --sizes 50,100
    .venv/bin/python bench/bench_success.py --quick            # 2 seeds of each
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, machine, median

from reconswarm.scenario.generate import generate
from reconswarm_bringup.sweep import Job, percentile, run_sweep

LARGE_OBSTACLES = 8


def small_params(seed: int) -> tuple[int, int]:
    """(agents, obstacles) of a seed of the small suite."""
    return 10 + (13 * seed) % 21, 4 + (seed // 2) % 3


def jobs(cases: list[tuple[int, int, int]], out: Path) -> list[Job]:
    """One job per (agents, obstacles, seed), the generated scenario as it is."""
    res = []
    for n, m, seed in cases:
        s = generate(n, m, seed)
        res.append(Job(s.meta.name, s, str(out / s.meta.name)))
    return res


def reason(r: dict[str, Any], duration_s: float) -> str:
    why = []
    if not r["converged"]:
        why.append(f"not converged within {duration_s:.0f} s (final max |e| {r['final_max_error_m']} m)")
    if r["collisions"]:
        why.append(f"{r['collisions']} collision(s) (min agent gap {r['min_agent_gap_m']} m, "
                   f"min obstacle gap {r['min_obstacle_gap_m']} m)")
    return "; ".join(why)


def report(title: str, js: list[Job], rows: list[dict[str, Any]]) -> None:
    ok = [r for r in rows if r["converged"] and not r["collisions"]]
    conv = [float(r["convergence_time_s"]) for r in rows if r["converged"]]
    med, p90 = percentile(conv, 50), percentile(conv, 90)
    print(f"{title}: success {len(ok)}/{len(rows)} = {100.0 * len(ok) / len(rows):.0f} %, "
          f"converged {len(conv)}/{len(rows)}, convergence time median "
          f"{'-' if med is None else f'{med:.1f}'} s, p90 {'-' if p90 is None else f'{p90:.1f}'} s, "
          f"contacts {sum(r['collisions'] for r in rows)} collision / "
          f"{sum(r['safety_violations'] for r in rows)} safety-band episode(s), mission wall median "
          f"{median([r['wall_time_s'] for r in rows]):.1f} s")
    for job, r in zip(js, rows, strict=True):
        if r not in ok:
            print(f"  failed {job.label} (N={len(job.scenario.agents)}, M={len(job.scenario.obstacles)}): "
                  f"{reason(r, job.scenario.meta.duration_s)}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--suite", choices=("small", "large", "all"), default="all")
    ap.add_argument("--seeds", type=int, default=None, help="seeds 0..S-1 (default 50 small, 10 large)")
    ap.add_argument("--sizes", default="50,100,200", help="agents of the large suite (default 50,100,200)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="smoke run: 2 seeds of each")
    args = ap.parse_args()
    sizes = [int(x) for x in args.sizes.split(",")]
    print(f"# bench_success: suite {args.suite}, generated scenarios, full duration, in-process engine, "
          f"sweep runner on ProcessPoolExecutor({args.workers}, spawn)")
    print(f"# {machine()}")
    print(f"# reproduce: {command_line()}")
    suites: list[tuple[str, list[tuple[int, int, int]]]] = []
    if args.suite in ("small", "all"):
        n_seeds = 2 if args.quick else (args.seeds or 50)
        suites.append((f"small (seeds 0..{n_seeds - 1}, N 10..30, M 4..6)",
                       [(*small_params(s), s) for s in range(n_seeds)]))
    if args.suite in ("large", "all"):
        n_seeds = 2 if args.quick else (args.seeds or 10)
        for n in sizes:
            suites.append((f"large N={n} M={LARGE_OBSTACLES} (seeds 0..{n_seeds - 1})",
                           [(n, LARGE_OBSTACLES, s) for s in range(n_seeds)]))
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_success_") as tmp, \
            ProcessPoolExecutor(args.workers, mp_context=get_context("spawn")) as pool:
        for title, cases in suites:
            js = jobs(cases, Path(tmp))
            t1 = time.perf_counter()
            rows = run_sweep(js, pool)
            report(title, js, rows)
            print(f"  ({len(rows)} runs in {time.perf_counter() - t1:.0f} s)", flush=True)
    print(f"wall: {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
