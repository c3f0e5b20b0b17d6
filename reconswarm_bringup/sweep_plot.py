"""`reconswarm sweep --plot FILE.png`: success and convergence time by planner, one column of panels per suite.

A suite is the directory the scenario files come from (the paper's file alone, a generated suite of many).
Top panel: the share of runs that converged (light) and that converged without a collision (dark). Bottom
panel: each converged run's convergence time (a box per planner, its median marked). Planners in order of
first appearance in results.csv."""

from __future__ import annotations

import csv
from pathlib import Path

from reconswarm.errors import BadInput


def suite_of(label: str) -> str:
    """The suite a scenario file belongs to: its directory's name, or the file's stem at the top level."""
    p = Path(label)
    return p.parent.name or p.stem


Row = dict[str, str]  # one line of results.csv, as csv.DictReader gives it


def by_suite(rows: list[Row]) -> dict[str, dict[str, list[Row]]]:
    """results.csv's rows by suite, then by planner, each in order of first appearance."""
    out: dict[str, dict[str, list[Row]]] = {}
    for r in rows:
        out.setdefault(suite_of(r["scenario"]), {}).setdefault(r["planner"], []).append(r)
    return out


def converged(rows: list[Row]) -> list[Row]:
    return [r for r in rows if r["converged"] == "True"]


def plot(results_csv: Path, png: Path) -> int:
    """Draw the figure of results.csv into png; returns the number of panels' columns (suites)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with results_csv.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise BadInput(f"--plot: {results_csv} holds no run to plot")
    planners = list(dict.fromkeys(r["planner"] for r in rows))
    grouped = by_suite(rows)
    files = {suite: {r["scenario"] for rs in by.values() for r in rs} for suite, by in grouped.items()}
    suites: dict[str, dict[str, tuple[int, int, int, list[float]]]] = {
        suite: {kind: (len(rs), len(ok := converged(rs)), sum(int(r["collisions"]) == 0 for r in ok),
                       [float(r["convergence_time_s"]) for r in ok]) for kind, rs in by.items()}
        for suite, by in grouped.items()}
    fig, axes = plt.subplots(2, len(suites), figsize=(1.4 + 0.9 * len(planners) * len(suites), 6.5), squeeze=False,
                             sharex="col")
    for c, (suite, by) in enumerate(suites.items()):
        kinds = [k for k in planners if k in by]
        xs = list(range(len(kinds)))
        top, bottom = axes[0][c], axes[1][c]
        top.bar(xs, [100.0 * by[k][1] / by[k][0] for k in kinds], color="#a6dba0", label="converged")
        top.bar(xs, [100.0 * by[k][2] / by[k][0] for k in kinds], color="#1b7837", label="converged, no collision")
        for x, k in zip(xs, kinds, strict=True):
            top.text(x, 2, f"{by[k][2]}/{by[k][1]}/{by[k][0]}", ha="center", va="bottom", fontsize=7, color="white")
        if c == 0:
            top.legend(loc="lower left", bbox_to_anchor=(0.0, 1.08), fontsize=7, ncol=2, frameon=False)
        top.set_ylim(0, 105)
        top.set_title(f"{suite} ({len(files[suite])} file{'s' * (len(files[suite]) != 1)})")
        top.set_ylabel("converged (%)" if c == 0 else "")
        data = [by[k][3] or [float("nan")] for k in kinds]
        bottom.boxplot(data, positions=xs, widths=0.6, whis=(10, 90), showfliers=True)
        bottom.set_ylabel("convergence time (s)" if c == 0 else "")
        bottom.set_xticks(xs, kinds, rotation=35, ha="right")
    fig.suptitle("reconswarm sweep by planner: runs converged (no collision / converged / runs), convergence time "
                 "(whiskers p10-p90)", fontsize=10)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return len(suites)
