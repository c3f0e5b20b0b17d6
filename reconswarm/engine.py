"""The in-process engine: the whole mission in one process, every agent at once, same functions as the
distributed deployment (agent.planner, agent.knowledge, agent.deadlock, agent.leader, simworld.*,
monitor.*). Deterministic for a scenario and seed.

Tick k, in this order (the agent process follows the same order for its own row):
  1. sense: every agent's scan of contour points within R_v of p_i(k);
  2. share: K_i(k) = K_i(k-1) ∪ scan_i(k) ∪ K_j(k-1) of every j within link range at tick k;
  3. plan: u_i(k) from p(k), neighbours within d_max,ij, known hulls, stall perturbation
     (virtual leader: the leader's step on the union of K(k-1) first);
  4. record tick k (truth, safety episodes, topology events); stop if every |e_i| <= tol;
  5. integrate the unicycles over dt under u(k).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agent.deadlock import StallState, generator, stall_step, window_ticks
from agent.knowledge import SwarmKnowledge, obstacle_view
from agent.leader import VirtualLeader
from agent.planner import command, errors, neighbour_table
from monitor.record import RunRecord, RunWriter
from monitor.recorder import Recorder
from monitor.summary import summarize
from monitor.topology import HYSTERESIS_M
from reconswarm.geometry import norm2, pairs_within
from reconswarm.scenario import Scenario
from simworld import unicycle
from simworld.sensing import ContourField

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SimConfig:
    scenario: Scenario
    out_dir: Path
    progress: bool = False
    record: bool = True


class Engine:
    """The swarm's state and one tick of the mission over all agents."""

    def __init__(self, s: Scenario) -> None:
        self.s = s
        self.cfg = s.planner
        self.n = len(s.agents)
        self.ids = s.ids
        self.r = s.radii
        self.offsets = s.offsets
        self.l = s.head_offsets
        self.target = np.asarray(s.target_m, dtype=np.float64)
        self.p = s.starts.copy()
        self.theta = s.headings.copy()
        self.field = ContourField.from_scenario(s)
        self.know = SwarmKnowledge(self.field.samples, self.field.start, self.field.count, self.n)
        w = window_ticks(self.cfg.stall_window_s, s.meta.dt_s)
        self.stall = StallState.create(self.n, w, [generator(s.meta.seed, int(i)) for i in self.ids])
        self.leader = VirtualLeader(s) if self.cfg.kind == "virtual-leader" else None
        self.rmax = float(self.r.max())
        self.true_d = np.zeros((self.n, self.field.n_obstacles))
        self.reach_m = max(self.cfg.link_range_m + HYSTERESIS_M, 2 * self.rmax + self.cfg.d_max_m)
        self.near = np.zeros((0, 2), dtype=np.int64)
        # True distances matter up to the sensing range and the repulsion reach; beyond, a bound will do.
        self.exact_within_m = max(self.cfg.sensing_range_m, self.rmax + self.cfg.d_max_m)

    def plan(self, k: int) -> Array:
        """Steps 1-3 for tick k: returns u (N, 2); leaves true distances in self.true_d."""
        c, p = self.cfg, self.p
        self.true_d = self.field.true_distances(p, self.exact_within_m)
        qa, qs = self.field.scan(p, c.sensing_range_m, self.true_d)
        self.near = pairs_within(p, self.reach_m)  # (E, 2) superset of every pair any step needs
        d_near = norm2(p[self.near[:, 0]] - p[self.near[:, 1]])
        prev = self.know.bits.copy()
        self.know.add(qa, qs)
        self.know.share(prev, self.near[d_near <= c.link_range_m])

        nb = neighbour_table(p, self.r, self.near, c.d_max_m)
        entries = []  # (agent, column, hull); columns keep obstacle-id order, empty ones are left out
        for m in range(self.field.n_obstacles):
            near = np.flatnonzero(self.true_d[:, m] <= self.r + c.d_max_m)
            if near.size:
                knows = self.know.knows(m)
                col = len({e[1] for e in entries})
                entries += [(int(i), col, self.know.hull(int(i), m)) for i in near if knows[i]]
        ob = obstacle_view(p, self.n, len({e[1] for e in entries}), entries)

        if self.leader is not None:
            hulls = [h for h in (self.know.union_hull(m, prev) for m in range(self.field.n_obstacles))
                     if h is not None]
            v, vel = self.leader.step(k, hulls)
            center = np.broadcast_to(v, (self.n, 2))
            lead_vel: Array | None = np.broadcast_to(vel, (self.n, 2))
        else:
            center, lead_vel = np.broadcast_to(self.target, (self.n, 2)), None
        e_track = errors(p, center, self.offsets)
        pert = stall_step(self.stall, k, p, e_track, c.perturbation_mps, c.k_att, c.target_radius_m,
                          c.converge_tol_m, self.s.meta.dt_s)
        return command(c, p, self.r, self.offsets, center, nb, ob, pert, lead_vel)

    def advance(self, u: Array) -> None:
        w = self.s.world
        self.p, self.theta = unicycle.step(self.p, self.theta, u, self.l, self.s.meta.dt_s,
                                           w.max_speed_mps, w.max_turn_rate_radps)


def run(cfg: SimConfig) -> dict[str, Any]:
    """Run the mission; write OUTDIR/run.db; return the summary."""
    s = cfg.scenario
    db = cfg.out_dir / "run.db"
    writer = RunWriter(db, s, "inprocess") if cfg.record else None
    eng = Engine(s)
    rec = Recorder(s, writer)
    alive = np.ones(eng.n, dtype=bool)
    n_ticks = round(s.meta.duration_s / s.meta.dt_s)
    wall0 = time.perf_counter()
    progress = _progress(cfg.progress, n_ticks)
    k = 0
    for k in range(n_ticks + 1):
        t = k * s.meta.dt_s
        u = eng.plan(k)
        rec.tick(k, t, eng.p, eng.theta, alive, eng.true_d, eng.near)
        if progress is not None and k % 20 == 0:
            progress(k, rec.max_error_m)
        if rec.converged() or k == n_ticks:
            break
        eng.advance(u)
    wall = time.perf_counter() - wall0
    if progress is not None:
        progress(-1, rec.max_error_m)
    extra = {"stalls": int(eng.stall.stalls.sum()),
             "agent_steps_per_s": round(eng.n * (k + 1) / wall, 1) if wall > 0 else None}
    if writer is None:
        return {"ticks": k + 1, "wall_time_s": wall, "converged": rec.converged(), **extra}
    writer.close(wall_time_s=f"{wall:.6f}", finished="1", extra=extra)
    record = RunRecord(db)
    try:
        return summarize(record)
    finally:
        record.close()


def _progress(enabled: bool, total: int) -> Any:
    if not enabled or not sys.stderr.isatty():
        return None
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    bar = Progress(TextColumn("sim"), BarColumn(), TextColumn("{task.completed}/{task.total} ticks"),
                   TextColumn("max |e| {task.fields[err]:.1f} m"), TimeElapsedColumn(), transient=True)
    task = bar.add_task("sim", total=total, err=float("inf"))
    bar.start()

    def update(k: int, err: float) -> None:
        if k < 0:
            bar.stop()
        else:
            bar.update(task, completed=k, err=err)

    return update
