"""Safety metrics from ground truth: surface gaps and contact episodes. Pure.

Gaps are surface gaps (docs/wire.md): ‖p_i - p_j‖ - r_i - r_j between robots and
dist(p_i, obstacle) - r_i to obstacles, over every body in the world (a stopped robot is still a body).
An episode is a maximal stretch of ticks during which one pair stays below the threshold: below 0 a
collision, below d_safe a safety violation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.pairs import pairs_and_distances, pairs_within
from reconswarm.geometry.plane import norm2

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Episode:
    kind: str  # "collision" | "safety"
    a: str  # "agent:<id>"
    b: str  # "agent:<id>" | "obstacle:<id>"
    t_start: float
    gap_m: float


def agent_gaps(p: Array, r: Array, reach_m: float, cand: NDArray[np.int64] | None = None,
               cand_d: Array | None = None) -> tuple[NDArray[np.int64], Array]:
    """Surface gaps of candidate pairs (default: every pair within 2 r_max + reach_m).

    cand_d (E,): optionally the candidates' norm2 distances. -> pairs (E, 2), gaps (E,)
    """
    if cand is None:
        cand = pairs_within(p, 2 * float(r.max()) + reach_m) if p.shape[0] > 1 else np.zeros((0, 2), np.int64)
        cand_d = None
    pairs = cand
    d = norm2(p[pairs[:, 0]] - p[pairs[:, 1]]) if cand_d is None else cand_d
    gaps = d - r[pairs[:, 0]] - r[pairs[:, 1]]
    return pairs, gaps


def nearest_gap(p: Array, r: Array) -> float:
    """The smallest surface gap over all pairs, exactly (used when no pair is close); inf for one robot.

    Pairs within a search radius R are measured (pairs_and_distances, exact); a pair beyond R has a gap
    above R - 2 r_max, so once the smallest gap found is at most that, it is the smallest of all. R starts
    at the mean spacing of the points and doubles until then. Points that are not finite are in no pair.
    """
    fin = np.isfinite(p[:, 0]) & np.isfinite(p[:, 1])
    if int(fin.sum()) < 2:
        return float("inf")
    q, rq = p[fin], r[fin]
    span = float(max(np.ptp(q[:, 0]), np.ptp(q[:, 1])))
    two_r = 2 * float(rq.max())
    radius = max(span / math.sqrt(q.shape[0]), two_r, 1e-9)
    best = float("inf")
    while True:
        pairs, d = pairs_and_distances(q, radius)
        if pairs.shape[0]:
            ri, rj = rq[pairs[:, 0]], rq[pairs[:, 1]]
            best = float(np.minimum(d - ri - rj, d - rj - ri).min())  # as seen from either end
            if best <= radius - two_r:
                return best
        if radius > 2 * span + two_r:  # every pair is within radius: best is the minimum
            return best
        radius *= 2


@dataclass
class SafetyMonitor:
    ids: NDArray[np.int64]  # (N,)
    radii: Array  # (N,)
    obstacle_ids: tuple[str, ...]
    d_safe_m: float
    reach_m: float = 10.0  # candidate pairs cover every pair within 2 r_max + reach_m
    open: dict[tuple[str, str, str], float] = field(default_factory=dict)  # key -> t_start
    min_agent_gap_m: float = float("inf")
    min_obstacle_gap_m: float = float("inf")
    _pairs_raw: bytes = b"\x00"  # the candidate pairs whose radii are _ri, _rj
    _ri: Array = field(default_factory=lambda: np.zeros(0))
    _rj: Array = field(default_factory=lambda: np.zeros(0))

    def step(self, t: float, p: Array, ob_d: Array, cand: NDArray[np.int64] | None = None,
             cand_d: Array | None = None) -> tuple[float, float, list[Episode], list[tuple[str, str, str]]]:
        """p (N, 2), ob_d (N, M) signed distances to the true obstacles; cand optional candidate pairs
        (a superset of those within 2 r_max + reach_m), cand_d optionally their norm2 distances (E,).

        Returns (min agent gap, min obstacle gap) at this tick, the episodes that start now and the keys
        (kind, a, b) of those that ended.
        """
        reach = max(self.reach_m, self.d_safe_m)
        if cand is not None and cand_d is not None:  # agent_gaps, with the pairs' radii kept while they last
            raw = cand.tobytes()
            if raw != self._pairs_raw:
                self._pairs_raw, self._ri, self._rj = raw, self.radii[cand[:, 0]], self.radii[cand[:, 1]]
            pairs, gaps = cand, cand_d - self._ri - self._rj
        else:
            pairs, gaps = agent_gaps(p, self.radii, reach, cand, cand_d)
        # Pairs outside the candidates have a gap of at least `reach`: the minimum is exact below it.
        tick_agent = float(gaps.min()) if gaps.size else float("inf")
        if tick_agent > reach and p.shape[0] > 1:
            tick_agent = min(tick_agent, nearest_gap(p, self.radii))
        ob_gap = ob_d - self.radii[:, None] if ob_d.size else np.zeros((p.shape[0], 0))
        tick_ob = float(ob_gap.min()) if ob_gap.size else float("inf")
        self.min_agent_gap_m = min(self.min_agent_gap_m, tick_agent)
        self.min_obstacle_gap_m = min(self.min_obstacle_gap_m, tick_ob)
        now: dict[tuple[str, str, str], float] = {}
        if tick_agent < self.d_safe_m:  # some candidate pair is below d_safe
            close = gaps < self.d_safe_m  # (E,)
            for (i, j), g in zip(pairs[close].tolist(), gaps[close].tolist(), strict=True):
                a, b = f"agent:{self.ids[i]}", f"agent:{self.ids[j]}"
                now[("safety", a, b)] = g
                if g < 0:
                    now[("collision", a, b)] = g
        if tick_ob < self.d_safe_m:
            below = ob_gap < self.d_safe_m  # (N, M)
            for i, m in zip(*np.nonzero(below), strict=True):
                g = float(ob_gap[i, m])
                a, b = f"agent:{self.ids[i]}", f"obstacle:{self.obstacle_ids[m]}"
                now[("safety", a, b)] = g
                if g < 0:
                    now[("collision", a, b)] = g
        started = [Episode(k[0], k[1], k[2], t, g) for k, g in now.items() if k not in self.open]
        ended = [k for k in self.open if k not in now]
        for k in ended:
            del self.open[k]
        for e in started:
            self.open[(e.kind, e.a, e.b)] = t
        return tick_agent, tick_ob, started, ended
