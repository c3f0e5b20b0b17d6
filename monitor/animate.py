"""`monitor animate`: the run as a moving picture, the paper's Fig. 4 in motion.

Top, the whole mission: obstacles, the attraction disk, the target slots and every head point's track so
far. Below, a window that follows the swarm: agents drawn to scale as discs coloured by group (connected
component of the swarm graph, same colours as the plot and the MCAP scene), the graph's links, slots and
obstacles. The record keeps no agent's knowledge of the obstacles, so both panels show the true ones.

Frame i shows the last recorded tick at or before t0 + i·speed/fps (simulated time runs `speed` times
faster than the picture); there are floor((t_end - t0)·fps/speed) + 1 frames.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.scene import GROUP_RGB, NOT_ALIVE_RGB, SwarmGraph
from reconswarm.errors import BadInput
from reconswarm.record.store import RunRecord

FORMATS = (".gif", ".mp4")


@dataclass(frozen=True)
class AnimationStats:
    path: Path
    frames: int
    bytes: int
    fps: int
    speed: float


def frame_times(t0: float, t_end: float, fps: int, speed: float) -> np.ndarray:
    """Simulated time of every frame."""
    n = math.floor((t_end - t0) * fps / speed + 1e-9) + 1
    return t0 + np.arange(n) * (speed / fps)


def check_request(out: Path, fps: int, speed: float) -> str:
    """Validate the output and rates before any work; -> the writer's name."""
    suffix = out.suffix.lower()
    if suffix not in FORMATS:
        raise BadInput(f"{out}: unknown animation format {out.suffix or '(none)'!r} (.gif or .mp4)")
    if not 1 <= fps <= 50:
        raise BadInput(f"--fps: {fps} is not in 1..50")
    if not (math.isfinite(speed) and speed > 0):
        raise BadInput(f"--speed: {speed} is not a positive number")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise BadInput(f"{out}: cannot write (no directory {parent})")
    if out.is_dir():
        raise BadInput(f"{out}: is a directory")
    existed = out.exists()
    try:
        out.open("ab").close()  # writable? (the writer opens it only after every frame is drawn)
    except OSError as exc:
        raise BadInput(f"{out}: cannot write ({exc.strerror})") from None
    if not existed:
        out.unlink()
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise BadInput(f"{out}: MP4 needs ffmpeg on PATH (not found); write a .gif instead")
    return "pillow" if suffix == ".gif" else "ffmpeg"


def animate_run(rec: RunRecord, out: Path, fps: int = 10, speed: float = 20.0, dpi: float = 72.0,
                progress: Callable[[int, int], None] | None = None, still_at_s: float | None = None) -> AnimationStats:
    """Write the animation (GIF or MP4 by out's suffix). With still_at_s, write only the frame at that
    simulated time as an image (PNG) instead."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle, Polygon

    writer_name = check_request(out, fps, speed) if still_at_s is None else ""
    s = rec.scenario
    tk = rec.ticks()
    if tk.t.size == 0:
        raise BadInput(f"{rec.path}: the record holds no ticks yet")
    times = frame_times(float(tk.t[0]), float(tk.t[-1]), fps, speed) if still_at_s is None \
        else np.array([still_at_s])
    rows = np.maximum(np.searchsorted(tk.t, times + 1e-9, side="right") - 1, 0)
    # The swarm graph at every tick (its links' hysteresis needs each one), kept for the frames' rows.
    graph = SwarmGraph(s.planner.link_range_m)
    want = set(rows.tolist())
    links: dict[int, np.ndarray] = {}
    groups: dict[int, np.ndarray] = {}
    for row in range(int(rows.max()) + 1):
        e, g = graph.step(np.stack([tk.px[row], tk.py[row]], axis=1), tk.alive[row])
        if row in want:
            links[row], groups[row] = e, g

    ids, radii = rec.ids, s.radii
    slots = np.asarray(s.target_m) + s.offsets
    fig, (ax_all, ax) = plt.subplots(2, 1, figsize=(8, 6.2), gridspec_kw={"height_ratios": [1, 1.9]})
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.05, top=0.9, hspace=0.22)
    for a in (ax_all, ax):
        for k in range(len(s.obstacles)):
            a.add_patch(Polygon(s.polygon(k), closed=True, fc="0.75", ec="0.3", lw=0.8, zorder=1))
        a.add_patch(Circle(s.target_m, s.planner.target_radius_m, fill=False, ls="--", ec="0.55", lw=0.7))
        a.plot(slots[:, 0], slots[:, 1], "k+", ms=5, mew=0.8, zorder=2)
        a.set_aspect("equal")
        a.tick_params(labelsize=7)
    polys = [s.polygon(k) for k in range(len(s.obstacles))]
    xs = np.concatenate([tk.px[np.isfinite(tk.px)], slots[:, 0], *[q[:, 0] for q in polys]])
    ys = np.concatenate([tk.py[np.isfinite(tk.py)], slots[:, 1], *[q[:, 1] for q in polys]])
    pad = 0.05 * max(np.ptp(xs), np.ptp(ys), 1.0)
    ax_all.set_xlim(xs.min() - pad, xs.max() + pad)
    ax_all.set_ylim(ys.min() - pad, ys.max() + pad)
    box = ax.get_position(original=True)
    zoom_aspect = box.width * fig.get_figwidth() / (box.height * fig.get_figheight())  # the window fills its panel
    ax_all.set_title("the mission", fontsize=9)
    ax.set_title("following the swarm (to scale)", fontsize=9)

    def colour(g: int, alive: bool) -> tuple[float, float, float]:
        return NOT_ALIVE_RGB if g < 0 or not alive else GROUP_RGB[g % len(GROUP_RGB)]

    tracks = [ax_all.plot([], [], "-", lw=0.6, color="0.35", zorder=2)[0] for _ in ids]
    dots = ax_all.scatter(np.zeros(len(ids)), np.zeros(len(ids)), s=9, zorder=3)
    discs = [ax.add_patch(Circle((0.0, 0.0), float(r), ec="k", lw=0.5, alpha=0.9, zorder=4)) for r in radii]
    heads = LineCollection([], colors="k", lw=0.8, zorder=5)
    ax.add_collection(heads)
    link_lines = LineCollection([], lw=0.7, zorder=3)
    ax.add_collection(link_lines)
    title = fig.suptitle("", fontsize=11)
    name = f"{rec.meta.get('scenario', s.meta.name)} - {rec.meta.get('planner', s.planner.kind.value)}"

    def draw(i: int) -> None:
        row = int(rows[i])
        p = np.stack([tk.px[row], tk.py[row]], axis=1)
        known = np.isfinite(p).all(axis=1)
        alive = tk.alive[row]
        g = groups[row]
        cols = [colour(int(g[k]), bool(alive[k])) for k in range(len(ids))]
        for k, line in enumerate(tracks):
            line.set_data(tk.px[: row + 1, k], tk.py[: row + 1, k])
        dots.set_offsets(np.nan_to_num(p))
        dots.set_facecolors([(*c, 1.0 if known[k] else 0.0) for k, c in enumerate(cols)])
        for k, d in enumerate(discs):
            d.set_visible(bool(known[k]))
            if known[k]:
                d.set_center((float(p[k, 0]), float(p[k, 1])))
                d.set_facecolor(cols[k])
        th = tk.theta[row]
        tips = p + 1.6 * radii[:, None] * np.stack([np.cos(th), np.sin(th)], axis=1)
        heads.set_segments([np.array([p[k], tips[k]]) for k in np.flatnonzero(known)])
        e = links[row]
        link_lines.set_segments([np.array([p[a], p[b]]) for a, b in e.tolist()])
        link_lines.set_color([colour(int(g[a]), True) for a, _ in e.tolist()])
        live = p[known & alive] if (known & alive).any() else p[known]
        if live.size:
            c0 = live.mean(axis=0)
            half = max(50.0, 0.6 * float(np.ptp(live, axis=0).max()) + 25.0)
            ax.set_xlim(c0[0] - zoom_aspect * half, c0[0] + zoom_aspect * half)
            ax.set_ylim(c0[1] - half, c0[1] + half)
        n_groups = int(g.max()) + 1
        title.set_text(f"{name}: t = {tk.t[row]:6.1f} s, {n_groups} group{'s' if n_groups != 1 else ''}")

    if still_at_s is not None:
        draw(0)
        fig.savefig(out, dpi=dpi)
        plt.close(fig)
        return AnimationStats(out, 1, out.stat().st_size, fps, speed)
    anim = animation.FuncAnimation(fig, draw, frames=len(times), interval=1000 / fps, repeat=False)
    writer = animation.PillowWriter(fps=fps) if writer_name == "pillow" else animation.FFMpegWriter(fps=fps)
    try:
        anim.save(str(out), writer=writer, dpi=dpi,
                  progress_callback=None if progress is None else (lambda i, n: progress(i + 1, n)))
    except OSError as exc:
        raise BadInput(f"{out}: cannot write ({exc.strerror or exc})") from None
    finally:
        plt.close(fig)
    return AnimationStats(out, len(times), out.stat().st_size, fps, speed)
