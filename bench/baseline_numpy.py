#!/usr/bin/env python3
"""A plain numpy implementation of the paper's law (docs/paper.md, eqs. 7-11): the yardstick the engine's speed
is measured against (bench/bench_engine.py). Written from the equations, independent of reconswarm.

Every tick: all pairs (N x N), the nearest point of every *true* obstacle for every agent (obstacle knowledge
ignored: every obstacle is known from the start), attraction (9), agent and obstacle repulsion (11), head-point
velocity u (7), explicit Euler on the head point p += u dt (the unicycle without actuator limits moves its
head point by exactly u dt) and the heading along u. No perturbation, no recording, no convergence stop:
the full duration of the scenario (300 s, 6000 ticks for the paper). Reads the scenario TOML itself.

    .venv/bin/python bench/baseline_numpy.py deploy/scenarios/paper.toml
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import time
import tomllib
from pathlib import Path

import numpy as np

PAPER = Path(__file__).resolve().parent.parent / "deploy" / "scenarios" / "paper.toml"


def load(path: Path) -> dict:
    return tomllib.loads(path.read_text())


def polygons(doc: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Obstacle edges padded to V: a (M, V, 2) edge starts, ab (M, V, 2) edge vectors, valid (M, V)."""
    polys = [np.array(o["vertices_m"], dtype=np.float64) for o in doc.get("obstacles", [])]
    v = max([1, *(len(p) for p in polys)])
    a = np.zeros((len(polys), v, 2))
    ab = np.zeros((len(polys), v, 2))
    valid = np.zeros((len(polys), v), dtype=bool)
    for m, poly in enumerate(polys):
        k = len(poly)
        a[m, :k] = poly
        ab[m, :k] = np.roll(poly, -1, axis=0) - poly
        valid[m, :k] = True
    return a, ab, valid


def run(doc: dict) -> tuple[int, float, np.ndarray]:
    """Simulate the whole duration; -> (ticks, final max tracking error, final positions)."""
    pl = doc["planner"]
    k_att, r_c, psi = pl["k_att"], pl["target_radius_m"], pl["psi_mps"]
    d_safe, d_max = pl["d_safe_m"], pl["d_max_m"]
    dt, duration = doc["scenario"]["dt_s"], doc["scenario"]["duration_s"]
    agents = doc["agents"]
    p = np.array([a["start_m"] for a in agents], dtype=np.float64)  # (N, 2)
    theta = np.array([a["heading_rad"] for a in agents], dtype=np.float64)
    r = np.array([a["radius_m"] for a in agents], dtype=np.float64)  # (N,)
    offset = np.array([a["offset_m"] for a in agents], dtype=np.float64)  # (N, 2)
    center = np.array(doc["target"]["center_m"], dtype=np.float64)
    a, ab, valid = polygons(doc)
    den = np.where(valid, (ab * ab).sum(axis=2), 1.0)  # (M, V)
    n = p.shape[0]
    eye = np.eye(n, dtype=bool)
    rr = r[:, None] + r[None, :]  # (N, N)
    dmin_a, dmax_a = rr + d_safe, rr + d_max
    dmin_o, dmax_o = (r + d_safe)[:, None], (r + d_max)[:, None]  # (N, 1)
    ticks = round(duration / dt)
    for _ in range(ticks):
        # Attraction, eq. (9), circular target region.
        rel = p - center
        dist = np.linalg.norm(rel, axis=1)
        inside = dist <= r_c
        u = np.where(inside[:, None], -k_att * (rel - offset),
                     -r_c * k_att * rel / np.maximum(dist, 1e-12)[:, None])
        # Agent repulsion, eq. (11), over all pairs.
        diff = p[:, None, :] - p[None, :, :]  # (N, N, 2)
        d = np.linalg.norm(diff, axis=2)
        act = (d <= dmax_a) & ~eye
        mag = np.where(act, -psi * (dmax_a - d) / (dmax_a - dmin_a), 0.0)
        u += (mag[..., None] * diff / np.where(eye, 1.0, np.maximum(d, 1e-12))[..., None]).sum(axis=1)
        if a.shape[0]:
            # Nearest point of every obstacle: project on every edge, keep the closest.
            ap = p[:, None, None, :] - a[None]  # (N, M, V, 2)
            t = np.clip((ap * ab[None]).sum(axis=3) / den[None], 0.0, 1.0)
            q = a[None] + t[..., None] * ab[None]  # (N, M, V, 2)
            vec = p[:, None, None, :] - q
            dv = np.linalg.norm(vec, axis=3)
            dv = np.where(valid[None], dv, np.inf)
            k = dv.argmin(axis=2)  # (N, M)
            do = np.take_along_axis(dv, k[..., None], axis=2)[..., 0]
            nv = np.take_along_axis(vec, k[..., None, None], axis=2)[:, :, 0, :] / np.maximum(do, 1e-12)[..., None]
            mag_o = np.where(do <= dmax_o, -psi * (dmax_o - do) / (dmax_o - dmin_o), 0.0)
            u += (mag_o[..., None] * nv).sum(axis=1)
        p = p + u * dt
        speed = np.linalg.norm(u, axis=1)
        theta = np.where(speed > 0.0, np.arctan2(u[:, 1], u[:, 0]), theta)
    err = np.linalg.norm(p - (center + offset), axis=1)
    return ticks, float(err.max()), p


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenario", nargs="?", type=Path, default=PAPER,
                    help="scenario TOML (default: deploy/scenarios/paper.toml)")
    path = ap.parse_args().scenario
    if not path.is_file():
        ap.error(f"{path}: file not found")
    t0 = time.perf_counter()
    ticks, err, _ = run(load(path))
    wall = time.perf_counter() - t0
    print(f"baseline_numpy: {path.name}: {ticks} ticks, {len(load(path)['agents'])} agents, "
          f"max |e| at the end {err:.3f} m, wall {wall:.3f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
