"""Draw one instant of an exported MCAP file as the Foxglove 3D panel would show it from above.

Reads the file with the `mcap` reader and its protobuf decoder (the `dev` extra), takes the last `/swarm`
and `/world` scene updates at or before the chosen simulated time and draws their entities as decoded:
discs (cylinders) with their colours, heading arrows, ids, the links, the obstacles' triangles, the slots
and the target disk. Nothing is taken from the run record, so the picture shows what the file holds.

    python docs/render_mcap_frame.py run.mcap --at 88.5 -o docs/mcap_frame.png
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import Circle, FancyArrow, Polygon
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory


def last_updates(path: Path, at_s: float) -> tuple[Any, Any, float]:
    """The last /world and /swarm updates at or before start + at_s, and the /swarm update's time (s)."""
    dec = DecoderFactory()
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            raise SystemExit(f"{path}: no summary with statistics (not written by `monitor export`?)")
        start = summary.statistics.message_start_time
        limit = start + round(at_s * 1e9)
        found: dict[str, tuple[int, Any]] = {}
        for schema, channel, msg in reader.iter_messages(topics=["/world", "/swarm"], ending_at=limit):
            decode = dec.decoder_for(channel.message_encoding, schema)
            if decode is not None:
                found[channel.topic] = (msg.log_time, decode(msg.data))
    return found["/world"][1], found["/swarm"][1], (found["/swarm"][0] - start) / 1e9


def rgba(c: Any) -> tuple[float, float, float, float]:
    return (c.r, c.g, c.b, c.a)


def draw(world: Any, swarm: Any, t_s: float, out: Path, title: str) -> None:
    fig, ax = plt.subplots(figsize=(8, 4.4))
    for e in world.entities:
        for tri in e.triangles:
            pts = [(q.x, q.y) for q in tri.points]
            for i in range(0, len(pts), 3):
                ax.add_patch(Polygon(pts[i:i + 3], closed=True, fc=rgba(tri.color), ec=rgba(tri.color), lw=0.4,
                                       zorder=1))
        for line in e.lines:
            xs = [q.x for q in line.points]
            ys = [q.y for q in line.points]
            ax.plot([*xs, xs[0]], [*ys, ys[0]], color=rgba(line.color), lw=0.8, zorder=1)
        for sp in e.spheres:
            ax.add_patch(Circle((sp.pose.position.x, sp.pose.position.y), sp.size.x / 2, fc=rgba(sp.color), zorder=2))
    centres = []
    for e in swarm.entities:
        for line in e.lines:  # the links: a line list, one colour per point
            pts = line.points
            for i in range(0, len(pts), 2):
                ax.plot([pts[i].x, pts[i + 1].x], [pts[i].y, pts[i + 1].y], color=rgba(line.colors[i]), lw=0.8,
                        zorder=3)
        for cyl in e.cylinders:
            x, y = cyl.pose.position.x, cyl.pose.position.y
            centres.append((x, y))
            ax.add_patch(Circle((x, y), cyl.size.x / 2, fc=rgba(cyl.color), ec="k", lw=0.5, zorder=4))
        for ar in e.arrows:
            q = ar.pose.orientation
            yaw = 2 * math.atan2(q.z, q.w)
            ax.add_patch(FancyArrow(ar.pose.position.x, ar.pose.position.y, ar.shaft_length * math.cos(yaw),
                                    ar.shaft_length * math.sin(yaw), width=ar.shaft_diameter,
                                    head_length=ar.head_length, head_width=ar.head_diameter, color=rgba(ar.color),
                                    length_includes_head=False, zorder=5))
        for tx in e.texts:
            ax.annotate(tx.text, (tx.pose.position.x, tx.pose.position.y), xytext=(5, 5), textcoords="offset points",
                        fontsize=7, zorder=6)
    cx = sum(c[0] for c in centres) / len(centres)
    cy = sum(c[1] for c in centres) / len(centres)
    ax.set_xlim(cx - 150, cx + 150)
    ax.set_ylim(cy - 80, cy + 80)
    ax.set_aspect("equal")
    ax.set_facecolor("0.97")
    ax.set_title(f"{title}: /world and /swarm at t = {t_s:.2f} s", fontsize=10)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", type=Path)
    ap.add_argument("--at", type=float, default=88.5, help="simulated time (s)")
    ap.add_argument("-o", "--out", type=Path, required=True)
    a = ap.parse_args()
    world, swarm, t_s = last_updates(a.mcap, a.at)
    draw(world, swarm, t_s, a.out, a.mcap.name)
    print(f"wrote {a.out} ({len(swarm.entities)} swarm entities at t = {t_s:.2f} s)")


if __name__ == "__main__":
    main()
