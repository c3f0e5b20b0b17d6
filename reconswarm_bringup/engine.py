"""The in-process engine: the whole mission in one process, every agent at once, same functions as the
distributed deployment (reconswarm.paper, reconswarm.plant, reconswarm.record). Deterministic for a scenario and seed.

Tick k, in this order (the agent process follows the same order for its own row):
  1. sense: every agent's scan of contour points within R_v of p_i(k);
  2. share: K_i(k) = K_i(k-1) ∪ scan_i(k) ∪ K_j(k-1) of every j within link range at tick k;
  3. plan: u_i(k) from p(k), neighbours within d_max,ij, known hulls, stall perturbation
     (virtual leader: the leader's step on the union of K(k-1) first);
  4. record tick k (truth, safety episodes, topology events); stop if every |e_i| <= tol;
  5. integrate the unicycles over dt under u(k).

Speed (the results are those of the plain computation, bit for bit): work is skipped only where it
provably contributes nothing (no sensing or obstacle table far from every obstacle, sharing only over the
knowledge that changed, exact obstacle distances only where they can matter), the pure functions get
the inputs they would compute themselves (pair distances, tracking errors) instead of recomputing them,
and what changes rarely is kept between ticks (the pairs within reach as a Verlet list, the neighbour
tables' and the obstacle table's layouts while the same agents are involved).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.pairs import NearPairs
from reconswarm.geometry.plane import Edges, rows_where
from reconswarm.paper.deadlock import Generators, StallState, window_ticks
from reconswarm.paper.knowledge import SwarmKnowledge, obstacle_view
from reconswarm.paper.leader import VirtualLeader
from reconswarm.paper.link import HYSTERESIS_M, linked
from reconswarm.paper.planner import NeighbourTables, ObstacleView, errors
from reconswarm.planners import registry
from reconswarm.planners.seam import Tick
from reconswarm.plant import unicycle
from reconswarm.plant.sensing import ContourField
from reconswarm.record.decimate import EveryNth
from reconswarm.record.recorder import Recorder, Rows
from reconswarm.record.store import RunRecord, RunWriter
from reconswarm.record.summary import summarize
from reconswarm.scenario.model import PlannerKind, Scenario
from reconswarm_bringup.outdir import ENGINE_MODE, RecordClaim

Array = NDArray[np.float64]


_NO_INDEX = np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class SimConfig:
    scenario: Scenario
    out_dir: Path
    progress: bool = False
    record: bool = True
    record_every: int = 1  # a tick row every this many ticks (and the last): reconswarm/record/decimate.py


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
        self.stall = StallState.create(self.n, w, Generators(s.meta.seed, self.ids.tolist()))
        self.leader = VirtualLeader(s) if self.cfg.kind == PlannerKind.VIRTUAL_LEADER else None
        self.rmax = float(self.r.max())
        self.true_d = np.zeros((self.n, self.field.n_obstacles))
        self.reach_m = max(self.cfg.link_range_m + HYSTERESIS_M, 2 * self.rmax + self.cfg.d_max_m)
        self.pairs = NearPairs(self.reach_m, 0.25 * self.reach_m)
        self.pairs(self.p)  # (the first call of a large swarm builds the candidate list: not in the mission loop)
        self.near = np.zeros((0, 2), dtype=np.int64)
        self.tables = NeighbourTables()  # the neighbour tables' layout, kept while the neighbours stay
        self.heard_tables = NeighbourTables()  # the same for the peers within link range (navground planners)
        self.planner = registry.make(s)
        self.near_d = np.zeros(0)  # (E,) norm2 distance of each pair in self.near
        self.slot_error: Array | None = None
        # True distances matter up to the sensing range and the repulsion reach; beyond, a bound will do.
        self.exact_within_m = max(self.cfg.sensing_range_m, self.rmax + self.cfg.d_max_m)
        self.ob_reach = self.r + self.cfg.d_max_m  # (N,) obstacle repulsion reach of each agent
        self.center = np.broadcast_to(self.target, (self.n, 2))  # (N, 2)
        self._no_obstacle = ObstacleView.empty(self.n)  # read-only, shared by every far tick
        self._edges_key: tuple[int, ...] = ()
        self._edges: tuple[list[Array], Edges] | None = None
        # The obstacle table's layout for (which agents reach which obstacles, knowledge version)
        self._view_key: tuple[bytes, int] = (b"", -1)
        self._view: tuple[int, NDArray[np.int64], NDArray[np.int64], Edges] | None = None

    def plan(self, k: int) -> Array:
        """Steps 1-3 for tick k: returns u (N, 2); leaves true distances in self.true_d."""
        c, p = self.cfg, self.p
        self.true_d = self.field.true_distances(p, self.exact_within_m, self.r)
        # Sensing and obstacle repulsion reach no farther than exact_within_m: far from every obstacle
        # (the common case) both are empty.
        near_any = self.true_d.size > 0 and float(self.true_d.min()) <= self.exact_within_m
        qa, qs = self.field.scan(p, c.sensing_range_m, self.true_d) if near_any else (_NO_INDEX, _NO_INDEX)
        # (E, 2) superset of every pair any step needs, and their distances
        self.near, self.near_d = self.pairs(p)
        self.know.update(qa, qs, rows_where(self.near, linked(self.near_d, c.link_range_m)))

        if self.leader is not None:
            hulls = [h for h in (self.know.union_hull_before(m) for m in range(self.field.n_obstacles))
                     if h is not None]
            v, vel = self.leader.step(k, hulls)
            center = np.broadcast_to(v, (self.n, 2))
            lead_vel: Array | None = np.broadcast_to(vel, (self.n, 2))
        else:
            center, lead_vel = self.center, None
        e_track = errors(p, center, self.offsets)
        # (N,) |p_i - (p* + Δ_i)|, the recorder's tracking error, when the centre is p* itself
        self.slot_error = e_track if self.leader is None else None
        t = Tick(k, self.s.meta.dt_s, p, self.theta, self.r, center, self.offsets, lead_vel, self.stall, e_track)
        if self.planner.needs_tables:
            t.nb = self.tables(p, self.r, self.near, c.d_max_m, self.near_d)
            t.ob = self._known_obstacles() if near_any else self._no_obstacle
        if self.planner.needs_hulls:
            heard = self.near_d <= c.link_range_m  # (E,) the pairs within link range (agent/brain.py: linked_at)
            t.heard = self.heard_tables(p, self.r, rows_where(self.near, heard), np.inf, self.near_d[heard])
            t.hulls = self._known_hulls()
        return self.planner.command(t)

    def _known_hulls(self) -> list[list[Array]]:
        """Every agent's known hulls, in obstacle-id order (what a navground planner is given)."""
        rows: list[list[Array]] = [[] for _ in range(self.n)]
        for m in range(self.field.n_obstacles):
            who = self.know.known[:, m].nonzero()[0]
            if who.size:
                for i, h in zip(who.tolist(), self.know.hulls(who, m), strict=True):
                    rows[i].append(h)
        return rows

    def _known_obstacles(self) -> ObstacleView:
        """The planner's obstacle table: each agent's known hull of every obstacle within its reach.

        Columns keep obstacle-id order; obstacles that no agent both reaches and knows are left out.
        """
        n = self.n
        if self.field.n_obstacles == 0:
            return ObstacleView.empty(n)
        reach = self.true_d <= self.ob_reach[:, None]  # (N, M)
        layout = (reach.tobytes(), self.know.version)
        if layout == self._view_key and self._view is not None:  # the same agents reach the same known hulls
            return obstacle_view(self.p, n, *self._view)
        cols = cast("NDArray[np.bool_]", reach.any(axis=0)).nonzero()[0]
        if cols.size == 0:
            return self._no_obstacle
        rows_l: list[NDArray[np.int64]] = []
        cols_l: list[NDArray[np.int64]] = []
        hulls: list[Array] = []
        col = 0
        for m in cols.tolist():
            near = reach[:, m].nonzero()[0]
            near = near[self.know.known[near, m]]
            if near.size:
                rows_l.append(near)
                cols_l.append(np.full(near.size, col, dtype=np.int64))
                hulls += self.know.hulls(near, m)
                col += 1
        if not hulls:
            return self._no_obstacle
        key = tuple(map(id, hulls))
        if self._edges is None or key != self._edges_key:  # else: the very same hulls as last time
            self._edges_key, self._edges = key, (hulls, Edges.of(hulls))  # held, so their ids stay theirs
        rows = rows_l[0] if len(rows_l) == 1 else np.concatenate(rows_l)
        cols_q = cols_l[0] if len(cols_l) == 1 else np.concatenate(cols_l)
        self._view_key, self._view = layout, (col, rows, cols_q, self._edges[1])
        return obstacle_view(self.p, n, col, rows, cols_q, self._edges[1])

    def advance(self, u: Array) -> None:
        """Move the robots under the planners' u, as the distributed world does: sent as (v, ω), applied as u."""
        w = self.s.world
        u = unicycle.through_inputs(u, self.theta, self.l)
        self.p, self.theta = unicycle.step(self.p, self.theta, u, self.l, self.s.meta.dt_s,
                                           w.max_speed_mps, w.max_turn_rate_radps)


def run(cfg: SimConfig) -> dict[str, Any]:
    """Run the mission; write OUTDIR/run.db; return the summary. OUTDIR is claimed first (RecordClaim):
    BadInput if a live run writes there or its run.db is a record the engine did not write."""
    if not cfg.record:
        return _run(cfg)
    with RecordClaim(cfg.out_dir):
        return _run(cfg)


def _run(cfg: SimConfig) -> dict[str, Any]:
    s = cfg.scenario
    db = cfg.out_dir / "run.db"
    writer = RunWriter(db, s, ENGINE_MODE) if cfg.record else None
    rows: Rows | None = writer
    if writer is not None and cfg.record_every > 1:
        rows = EveryNth(writer, cfg.record_every)
        writer.set_meta(record_every_ticks=str(cfg.record_every))
    eng = Engine(s)
    rec = Recorder(s, rows)
    alive = np.ones(eng.n, dtype=bool)
    n_ticks = round(s.meta.duration_s / s.meta.dt_s)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    progress = _progress(cfg.progress, n_ticks)
    k = 0
    for k in range(n_ticks + 1):
        t = k * s.meta.dt_s
        u = eng.plan(k)
        rec.tick(k, t, eng.p, eng.theta, alive, eng.true_d, eng.near, cand_d=eng.near_d, err=eng.slot_error)
        if progress is not None and k % 50 == 0:
            progress(k, rec.max_error_m)
        if rec.converged() or k == n_ticks:
            break
        eng.advance(u)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    if progress is not None:
        progress(-1, rec.max_error_m)
    extra = {"stalls": int(eng.stall.stalls.sum()),
             "agent_steps_per_s": round(eng.n * (k + 1) / wall, 1) if wall > 0 else None,
             "mission_cpu_s": round(cpu, 3)}  # the loop's CPU time (wall_time_s counts other processes' load too)
    if writer is None:
        return {"ticks": k + 1, "wall_time_s": wall, "converged": rec.converged(), **extra}
    if isinstance(rows, EveryNth):
        rows.finish()
    writer.close(wall_time_s=f"{wall:.6f}", finished="1", extra=extra)
    record = RunRecord(db, s)
    try:
        return summarize(record)
    finally:
        record.close()


def _progress(enabled: bool, total: int) -> Any:
    if not enabled or not sys.stderr.isatty():
        return None
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    bar = Progress(TextColumn("sim"), BarColumn(), TextColumn("{task.completed}/{task.total} ticks"),
                   TextColumn("max |e| {task.fields[err]:.1f} m"), TimeElapsedColumn(), transient=True,
                   refresh_per_second=4)  # its refresh thread competes with the mission loop for the GIL
    task = bar.add_task("sim", total=total, err=float("inf"))
    bar.start()

    def update(k: int, err: float) -> None:
        if k < 0:
            bar.stop()
        else:
            bar.update(task, completed=k, err=err)

    return update
