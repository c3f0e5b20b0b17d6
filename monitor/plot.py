"""`monitor plot`: one PNG that shows what happened in a run.

Top: every trajectory with the obstacles, starts and target slots. Middle: six snapshots like the
paper's Fig. 4, robots drawn to scale and coloured by swarm group (connected components of the swarm
graph at that instant). Bottom: the tracking error ‖p_i - (p* + Δ_i)‖ of every agent over time like
Fig. 5, with the split / merge / membership events marked.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from reconswarm.errors import BadInput
from reconswarm.paper.topology import graph_edges, labels
from reconswarm.record.store import RunRecord
from reconswarm.record.summary import convergence_time


def _snapshot_rows(t: np.ndarray, conv_t: float | None) -> list[int]:
    end = float(t[-1])
    paper = [0.0, 40.0, 80.0, 92.0, 110.0]  # the instants of the paper's Fig. 4
    times = [x for x in paper if x < end] if end > 120 else list(np.linspace(0, end, 6)[:-1])
    times = [*times[:5], conv_t if conv_t is not None else end]
    while len(times) < 6:
        times.insert(-1, end * len(times) / 6)
    return [int(np.argmin(np.abs(t - x))) for x in times]


def plot_run(rec: RunRecord, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    s = rec.scenario
    tk = rec.ticks()
    if tk.t.size == 0:
        raise BadInput(f"{rec.path}: the record holds no ticks yet")
    events = rec.events()
    ids, radii = rec.ids, s.radii
    slots = np.asarray(s.target_m) + s.offsets
    cmap = plt.get_cmap("tab10" if len(ids) <= 10 else "viridis")
    colours = [cmap(k % 10 if len(ids) <= 10 else k / max(1, len(ids) - 1)) for k in range(len(ids))]

    fig = plt.figure(figsize=(16, 15), constrained_layout=True)
    grid = fig.add_gridspec(4, 3, height_ratios=[1.3, 1, 1, 1])
    ax = fig.add_subplot(grid[0, :])

    def draw_world(a: plt.Axes) -> None:
        for k in range(len(s.obstacles)):
            a.add_patch(Polygon(s.polygon(k), closed=True, fc="0.75", ec="0.3", lw=1, zorder=1))
        a.plot(slots[:, 0], slots[:, 1], "k+", ms=6, zorder=2)
        a.add_patch(Circle(s.target_m, s.planner.target_radius_m, fill=False, ls="--", ec="0.5", lw=0.8))
        a.set_aspect("equal")

    draw_world(ax)
    step = max(1, tk.t.size // 2000)
    for k in range(len(ids)):
        ax.plot(tk.px[::step, k], tk.py[::step, k], "-", lw=0.9, color=colours[k],
                label=f"agent {ids[k]}" if len(ids) <= 12 else None)
        ax.plot(tk.px[0, k], tk.py[0, k], "o", ms=3, color=colours[k])
    if len(ids) <= 12:
        ax.legend(loc="upper left", fontsize=7, ncols=2)
    ax.set_title(f"{rec.meta.get('scenario')} — {rec.meta.get('planner')} ({rec.meta.get('mode')}): trajectories "
                 f"of the head points, obstacles, target slots (+) and B(p*, R_c)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")

    conv = convergence_time(tk.t, tk.max_error_m, s.planner.converge_tol_m)
    group_cmap = plt.get_cmap("Set1")
    for panel, row in enumerate(_snapshot_rows(tk.t, conv)):
        a = fig.add_subplot(grid[1 + panel // 3, panel % 3])
        draw_world(a)
        p = np.stack([tk.px[row], tk.py[row]], axis=1)
        alive = tk.alive[row] & np.isfinite(p[:, 0])
        lab = labels(len(ids), graph_edges(np.nan_to_num(p), alive, np.zeros((0, 2), np.int64),
                                           s.planner.link_range_m, 0.0), alive)
        groups = {g: n for n, g in enumerate(sorted(set(lab[lab >= 0].tolist())))}
        for k in map(int, np.flatnonzero(np.isfinite(p[:, 0]))):
            c = group_cmap(groups[lab[k]] % 9) if lab[k] >= 0 else "0.2"
            a.add_patch(Circle(p[k], radii[k], fc=c, ec="k", lw=0.5, alpha=0.85, zorder=3))
            a.plot([p[k, 0], slots[k, 0]], [p[k, 1], slots[k, 1]], ":", lw=0.4, color="0.6", zorder=0)
        span = max(120.0, float(np.nanmax(np.ptp(p, axis=0))) * 0.6 + 60)
        c0 = np.nanmean(p[alive] if alive.any() else p, axis=0)
        a.set_xlim(c0[0] - span, c0[0] + span)
        a.set_ylim(c0[1] - span * 0.75, c0[1] + span * 0.75)
        a.set_title(f"t = {tk.t[row]:.1f} s: {len(groups)} group{'s' if len(groups) != 1 else ''}", fontsize=10)
        a.tick_params(labelsize=7)

    ax2 = fig.add_subplot(grid[3, :])
    err = np.sqrt((tk.px - slots[:, 0]) ** 2 + (tk.py - slots[:, 1]) ** 2)
    for k in range(len(ids)):
        ax2.plot(tk.t[::step], np.maximum(err[::step, k], 1e-3), lw=0.9, color=colours[k])
    ax2.axhline(s.planner.converge_tol_m, color="k", ls="--", lw=0.8, label=f"tolerance {s.planner.converge_tol_m} m")
    marks = {"split": "tab:red", "merge": "tab:green", "agent_lost": "k", "agent_joined": "tab:blue"}
    seen: set[str] = set()
    for e in events:
        kind = e["kind"]
        ax2.axvline(e["t"], color=marks.get(kind, "0.5"), lw=0.8, alpha=0.7,
                    label=kind if kind not in seen else None)
        seen.add(kind)
    if conv is not None:
        ax2.axvline(conv, color="tab:purple", lw=1.5, label=f"converged at {conv:.2f} s")
    ax2.set_yscale("log")
    ax2.set_ylim(bottom=max(0.01, 0.1 * s.planner.converge_tol_m))
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("‖p_i − (p* + Δ_i)‖ (m)")
    ax2.set_title("tracking error per agent (paper Fig. 5) with topology events")
    ax2.legend(loc="upper right", fontsize=8)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)

