"""Success rate over generated scenarios with obstacles: a run succeeds when it converges (every
|e_i| <= tol) with zero collisions. Prints the rate, the total contact count (collision episodes, and
safety-band episodes beside), and every failing seed with its reason.

Seed s (0..49) uses N = 10 + (13 s mod 21) agents (10..30) and M = 4 + (floor(s / 2) mod 3) obstacles
(4..6):
`reconswarm scenario generate --agents N --obstacles M --seed s`, run to its own duration with the
in-process engine, two at a time (multiprocessing Pool, 2 workers, spawn context).

    .venv/bin/python bench/bench_success.py            # 50 seeds
    .venv/bin/python bench/bench_success.py --quick    # 2 seeds
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, machine, median


def params(seed: int) -> tuple[int, int]:
    """(agents, obstacles) of a seed."""
    return 10 + (13 * seed) % 21, 4 + (seed // 2) % 3


def run_seed(job: tuple[int, str]) -> dict[str, Any]:
    from reconswarm.generate import generate
    from reconswarm_bringup import engine

    seed, out = job
    n, m = params(seed)
    s = generate(n, m, seed)
    summary = engine.run(engine.SimConfig(s, Path(out) / f"seed{seed}", progress=False))
    return {"seed": seed, "agents": n, "obstacles": m, **{k: summary[k] for k in (
        "converged", "convergence_time_s", "collisions", "safety_violations", "final_max_error_m",
        "min_agent_gap_m", "min_obstacle_gap_m", "duration_s", "wall_time_s", "stalls")}}


def reason(r: dict[str, Any]) -> str:
    why = []
    if not r["converged"]:
        why.append(f"not converged within {r['duration_s']:.0f} s (final max |e| {r['final_max_error_m']} m)")
    if r["collisions"]:
        why.append(f"{r['collisions']} collision(s) (min agent gap {r['min_agent_gap_m']} m, "
                   f"min obstacle gap {r['min_obstacle_gap_m']} m)")
    return "; ".join(why)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=50, help="seeds 0..S-1 (default 50)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="smoke run: 2 seeds")
    args = ap.parse_args()
    seeds = list(range(2 if args.quick else args.seeds))
    lo = min(params(s)[0] for s in seeds)
    hi = max(params(s)[0] for s in seeds)
    print(f"# bench_success: seeds 0..{seeds[-1]}, N = 10 + (13 s mod 21) agents ({lo}..{hi}), "
          f"M = 4 + (s // 2 mod 3) obstacles, generated scenarios, full duration, in-process engine, "
          f"Pool({args.workers}, spawn)")
    print(f"# {machine()}")
    print(f"# reproduce: {command_line()}")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_success_") as tmp:
        ctx = mp.get_context("spawn")
        with ctx.Pool(args.workers) as pool:
            results = sorted(pool.map(run_seed, [(s, tmp) for s in seeds], chunksize=1), key=lambda r: r["seed"])
    wall = time.perf_counter() - t0
    ok = [r for r in results if r["converged"] and not r["collisions"]]
    conv = [r["convergence_time_s"] for r in results if r["converged"]]
    print(f"success: {len(ok)}/{len(results)} = {100.0 * len(ok) / len(results):.1f} % "
          f"(converged and zero collisions)")
    print(f"converged: {len(conv)}/{len(results)}; convergence time median "
          f"{median(conv) if conv else float('nan'):.2f} s")
    print(f"contacts: {sum(r['collisions'] for r in results)} collision episode(s), "
          f"{sum(r['safety_violations'] for r in results)} safety-band episode(s) in total; "
          f"stalls perturbed: {sum(r['stalls'] or 0 for r in results)}")
    print(f"wall: {wall:.1f} s for {len(results)} runs (mission wall median "
          f"{median([r['wall_time_s'] for r in results]):.3f} s)")
    failures = [r for r in results if r not in ok]
    print(f"failures: {len(failures)}")
    for r in failures:
        print(f"  seed {r['seed']:3d} (N={r['agents']}, M={r['obstacles']}): {reason(r)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
