#!/usr/bin/env python3
"""The comparison tables of docs/planners.md from one or more sweeps' results.csv: per suite (the directory of the
scenario files, as `reconswarm sweep --plot` groups them) one Markdown table, one line per planner, pooled over the
suite's files and seeds: runs, converged, converged without a collision, convergence time (median and p90 over the
converged runs), collision episodes (summed), runs with a collision, the least agent and obstacle gaps, the mean
path length and the mean splits / merges.

    .venv/bin/python bench/planner_tables.py sweep/results.csv [more/results.csv ...]
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import csv
from pathlib import Path

from reconswarm_bringup.sweep import percentile
from reconswarm_bringup.sweep_plot import Row, by_suite, converged

HEAD = ("| planner | runs | converged | converged, no collision | conv. time median (s) | p90 (s) | collision episodes "
        "| runs with a collision | min agent gap (m) | min obstacle gap (m) | path length, mean (m) "
        "| splits / merges, mean |")


def _s(v: float | None) -> str:
    return "–" if v is None else f"{v:.2f}"


def tables(paths: list[Path]) -> str:
    rows: list[Row] = []
    for p in paths:
        with p.open(newline="") as fh:
            rows += list(csv.DictReader(fh))
    out = []
    for suite, by in by_suite(rows).items():
        files = {r["scenario"] for rs in by.values() for r in rs}
        out += [f"### {suite} ({len(files)} files)", "", HEAD, "|---" * 12 + "|"]
        for planner, rs in by.items():
            ok = converged(rs)
            times = [float(r["convergence_time_s"]) for r in ok]
            hit = [r for r in rs if int(r["collisions"]) > 0]
            n = len(rs)
            out.append(" | ".join([
                f"| {planner}", str(n), str(len(ok)), str(sum(int(r["collisions"]) == 0 for r in ok)),
                _s(percentile(times, 50)), _s(percentile(times, 90)), str(sum(int(r["collisions"]) for r in rs)),
                str(len(hit)), _s(min(float(r["min_agent_gap_m"]) for r in rs)),
                _s(min(float(r["min_obstacle_gap_m"]) for r in rs)),
                f"{sum(float(r['path_length_mean_m']) for r in rs) / n:.0f}",
                f"{sum(int(r['splits']) for r in rs) / n:.1f} / {sum(int(r['merges']) for r in rs) / n:.1f} |"]))
        out.append("")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("results", nargs="+", type=Path, help="results.csv of `reconswarm sweep`")
    print(tables(ap.parse_args().results))


if __name__ == "__main__":
    main()
