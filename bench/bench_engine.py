#!/usr/bin/env python3
"""The engine against a plain numpy implementation of the same law (bench/baseline_numpy.py), paired.

Each repeat runs, one after the other and alternating which goes first, a fresh
`reconswarm sim SCENARIO --json` process and a fresh `python bench/baseline_numpy.py SCENARIO` process,
and takes each process's wall time and CPU time (user + sys, start-up and imports included). The figures
are medians over the repeats and the ratio is baseline / engine (above 1: the engine is faster). The
engine stops at convergence and records run.db; the baseline runs the full duration and records nothing.
On a shared machine wall time follows the load; CPU time is the steadier figure, and both are printed.

    .venv/bin/python bench/bench_engine.py                              # paper scenario, 5 pairs
    .venv/bin/python bench/bench_engine.py --repeats 9 deploy/scenarios/paper.toml
    .venv/bin/python bench/bench_engine.py --importtime                 # also: top start-up offenders
    .venv/bin/python bench/bench_engine.py --before ../old-checkout     # also another revision, same pairs

With --before DIR, a third process runs the same command from the source tree DIR (another checkout,
put first on PYTHONPATH), in the same rotation: before and after figures measured side by side.
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, fmt_list, machine, median

HERE = Path(__file__).resolve().parent


def timed(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float, str]:
    """Run cmd to completion: -> (wall s, CPU s of the child, its stdout)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env).stdout
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, out


def import_offenders(top: int) -> list[tuple[int, int, str]]:
    """`python -X importtime -c "import reconswarm_bringup.cli; import reconswarm_bringup.engine"`:
    the modules with the largest cumulative import time, (cumulative us, self us, name)."""
    code = "import reconswarm_bringup.cli, reconswarm_bringup.engine"
    err = subprocess.run([sys.executable, "-X", "importtime", "-c", code], check=True, capture_output=True,
                         text=True).stderr
    rows = []
    for line in err.splitlines():
        if not line.startswith("import time:") or "|" not in line or "self" in line:
            continue
        self_us, cum_us, name = line.removeprefix("import time:").split("|")
        rows.append((int(cum_us), int(self_us), name.rstrip()))
    rows.sort(reverse=True)
    return rows[:top]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenario", nargs="?", default="deploy/scenarios/paper.toml")
    ap.add_argument("--repeats", type=int, default=5, help="pairs of runs (default 5)")
    ap.add_argument("--before", type=Path, help="a checkout of another revision to time alongside")
    ap.add_argument("--importtime", action="store_true", help="also list the slowest imports of `reconswarm sim`")
    args = ap.parse_args()
    exe = Path(sys.executable).parent / "reconswarm"
    print(f"# bench_engine: {args.scenario}, {args.repeats} pairs, alternating order, fresh processes")
    print(f"# {machine()}")
    print(f"# reproduce: {command_line()}")
    names = ["engine", "baseline"] + (["before"] if args.before else [])
    runs: dict[str, tuple[list[float], list[float]]] = {name: ([], []) for name in names}
    summaries: dict[str, dict[str, object]] = {}
    with tempfile.TemporaryDirectory(prefix="bench_engine_") as tmp:
        sim = ["sim", args.scenario, "--json", "-o", os.path.join(tmp, "run")]
        cmds: dict[str, tuple[list[str], dict[str, str] | None]] = {"engine": ([str(exe), *sim], None),
                "baseline": ([sys.executable, str(HERE / "baseline_numpy.py"), args.scenario], None)}
        if args.before:
            env = {**os.environ, "PYTHONPATH": str(args.before.resolve())}
            main_code = "import sys; from reconswarm_bringup.cli import main; sys.argv[0] = 'reconswarm'; main()"
            cmds["before"] = ([sys.executable, "-P", "-c", main_code, *sim], env)  # -P: not the cwd first
        for r in range(args.repeats):
            for name in names[r % len(names):] + names[:r % len(names)]:  # rotate who goes first
                wall, cpu, out = timed(*cmds[name])
                runs[name][0].append(wall)
                runs[name][1].append(cpu)
                if name != "baseline":
                    summaries[name] = json.loads(out)
    for name, summary in summaries.items():
        print(f"{name}: converged {summary.get('converged')} at {summary.get('convergence_time_s')} s, "
              f"{summary.get('ticks')} ticks, splits {summary.get('splits')}, merges {summary.get('merges')}, "
              f"collisions {summary.get('collisions')}; mission loop {summary.get('wall_time_s')} s (last run)")
    if len(summaries) == 2 and summaries["engine"].get("path_length_m") != summaries["before"].get("path_length_m"):
        print("WARNING: engine and before differ in their path lengths")
    print(f"{'':10s} {'wall s median':>13s} {'cpu s median':>12s}  wall runs / cpu runs")
    for name, (walls, cpus) in runs.items():
        print(f"{name:10s} {median(walls):13.3f} {median(cpus):12.3f}  {fmt_list(walls)} / {fmt_list(cpus)}")
    ew, ec = median(runs["engine"][0]), median(runs["engine"][1])
    bw, bc = median(runs["baseline"][0]), median(runs["baseline"][1])
    print(f"ratio baseline / engine: wall {bw / ew:.2f}x, cpu {bc / ec:.2f}x")
    if args.before:
        ow, oc = median(runs["before"][0]), median(runs["before"][1])
        print(f"ratio baseline / before: wall {bw / ow:.2f}x, cpu {bc / oc:.2f}x")
    if args.importtime:
        print("# slowest imports of the engine's command (cumulative us, self us, module)")
        for cum, own, name in import_offenders(15):
            print(f"{cum:9d} {own:9d}  {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
