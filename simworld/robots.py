"""The world's robots (the plant its agents control): their unicycles under the commands they hold, and their
range sensing. Pure.

Each robot holds the input of its agent's latest command (`plant_input`: the head point's velocity of eq. 3 at
the heading the agent planned from, the zero-order hold the in-process engine uses) for `hold_sim_s`, then
stops. A command is held beyond its own tick (or taken late) only while its robot stands within
`hold_reach_m` (d_safe / 2) of where its agent planned it: the law is one short step from that point (the
paper's repulsion, |Ψ| = 65 m/s, moves a robot metres a tick), and driven from elsewhere it is that step moved
by as much, through whatever the law never saw there. Two robots each that near their plans lose at most d_safe
of the gap the law keeps. `observe` is what a tick publishes of it: the truth and every robot's state with its
scan (the contour points in sensing range and the held robots near it). The state machine around it is
simworld/world.py; ROS 2 mode's plant, a robot base holding (v, ω) itself, is simworld/ros2_io.Ros2Robots.
"""

from __future__ import annotations

import numpy as np

from reconswarm.net.wire import wire
from reconswarm.net.wire.cells import CellGrid
from reconswarm.paper.planner import errors
from reconswarm.plant import unicycle
from reconswarm.plant.sensing import ContourField
from reconswarm.scenario.model import Scenario


class Robots:
    def __init__(self, s: Scenario, hold_sim_s: float) -> None:
        self.s = s
        self.ids = [a.id for a in s.agents]
        self.index = {a: k for k, a in enumerate(self.ids)}
        self.p = s.starts.copy()
        self.theta = s.headings.copy()
        self.l = s.head_offsets
        self.field = ContourField.from_scenario(s)
        # Every contour sample as a scan reports it, (x, y, obstacle id), made once: obstacles do not move. (S,)
        self.sample_points = [(x, y, self.field.ids[o]) for (x, y), o in
                              zip(self.field.samples.tolist(), self.field.owner.tolist(), strict=True)]
        grid = CellGrid.for_scenario(s)
        # Held robots (agents gone) are reported in the scans of agents this near: nearer than anything that
        # can matter to them within the next tick (an agent hears only its cells' beacons).
        self.body_range_m = grid.reach_m + 2.0 * grid.step_m
        n = len(self.ids)
        self.hold_ticks = max(1, round(hold_sim_s / s.meta.dt_s))
        self.held = np.zeros((n, 2))  # each robot's held input to the plant (`plant_input` of its last command)
        self.held_k = np.full(n, -(10**9))  # tick of each robot's last command
        self.planned_p = self.p.copy()  # (N, 2) each robot's head point at its last command's tick
        self.hold_reach_m = s.planner.d_safe_m / 2.0
        self.halted = np.zeros(n, dtype=bool)  # (N,) the robots no command moved over the last step
        self.cmds: dict[int, dict[int, np.ndarray]] = {}  # tick -> agent index -> (v, ω)
        # The robots' poses at the recent ticks, tick -> (θ (N,), head points (N, 2)): a late command is its tick's.
        self.poses: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def command(self, agent_id: int, k: int, v_mps: float, omega_radps: float) -> None:
        """Agent agent_id's (v, ω) for tick k (a late one still counts as its latest, `apply`)."""
        self.cmds.setdefault(k, {})[self.index[agent_id]] = np.array([v_mps, omega_radps])

    def observe(self, k: int, alive: set[int]) -> tuple[wire.Truth, list[wire.State]]:
        """Tick k as published: the truth, and every robot's state with its scan (if anything is in range)."""
        t = k * self.s.meta.dt_s
        true_d = self.field.true_distances(self.p, self.s.planner.sensing_range_m)
        qa, qs = self.field.scan(self.p, self.s.planner.sensing_range_m, true_d)
        bodies = self.held_bodies(alive, k)
        counts = np.bincount(qa, minlength=len(self.ids)) + np.array([len(b) for b in bodies], dtype=np.int64)
        c = unicycle.body_centre(self.p, self.theta, self.l)
        truth = wire.Truth(k, t, tuple(self.ids), tuple(c[:, 0].tolist()), tuple(c[:, 1].tolist()),
                           tuple(self.theta.tolist()), tuple(self.p[:, 0].tolist()), tuple(self.p[:, 1].tolist()))
        scans: list[wire.Scan | None] = [None] * len(self.ids)
        starts = np.searchsorted(qa, np.arange(len(self.ids)))
        ends = np.searchsorted(qa, np.arange(len(self.ids)), side="right")
        for i in map(int, np.flatnonzero(counts)):
            pts = tuple(map(self.sample_points.__getitem__, qs[starts[i]:ends[i]].tolist()))
            scans[i] = wire.Scan(self.ids[i], k, t, pts, bodies[i])
        states = [wire.State(a, k, t, float(c[i, 0]), float(c[i, 1]), float(self.theta[i]), float(self.p[i, 0]),
                             float(self.p[i, 1]), scans[i]) for i, a in enumerate(self.ids)]
        return truth, states

    def held_bodies(self, alive: set[int], k: int = 0) -> list[tuple[tuple[int, float, float], ...]]:
        """Per robot: the held robots within body_range_m of its head point, as (agent id, head x, y): those whose
        agents are not in `alive`, and from tick 1 on those standing still because their agent's commands stopped
        `hold_sim_s` ago or never came (an agent alive by its token that never spoke is heard by nobody: without
        this its robot would be in nobody's plan) or because no command held them over the last step (its agent
        behind: `stopped`); none for a robot whose own agent is gone."""
        out: list[tuple[tuple[int, float, float], ...]] = [()] * len(self.ids)
        stopped = self.expired(k) | self.halted if k >= 1 else np.zeros(len(self.ids), dtype=bool)
        held = [i for i, a in enumerate(self.ids) if a not in alive or stopped[i]]
        if not held:
            return out
        hp = self.p[held]  # (H, 2)
        d = np.hypot(*(self.p[:, None, :] - hp[None, :, :]).transpose(2, 0, 1))  # (N, H)
        for i, a in enumerate(self.ids):
            if a in alive:
                out[i] = tuple((self.ids[held[j]], float(hp[j, 0]), float(hp[j, 1]))
                               for j in map(int, np.flatnonzero(d[i] <= self.body_range_m)) if held[j] != i)
        return out

    def expired(self, k: int) -> np.ndarray:
        """(N,) bool: the robots whose last command is older than `hold_sim_s` at tick k (or never came)."""
        return (k - self.held_k) > self.hold_ticks

    def stopped(self, k: int) -> np.ndarray:
        """(N,) bool: the robots no command holds over the step from tick k: expired, or standing farther than
        `hold_reach_m` from where their agents planned the command they hold (held beyond its tick, or late: the
        step is then the planned one moved by that much; a command of tick k moves it by exactly 0)."""
        return self.expired(k) | (np.hypot(*(self.p - self.planned_p).T) > self.hold_reach_m)

    def apply(self, k: int) -> set[int]:
        """Choose every robot's input for the step k -> k+1 and integrate; the agent indices commanded for k."""
        hold = self.hold_ticks
        self.poses[k] = self.theta.copy(), self.p.copy()
        for kk in [x for x in self.poses if x < k - hold - 1]:
            del self.poses[kk]
        got = self.cmds.pop(k, {})
        for kk in sorted(x for x in self.cmds if x < k):  # late commands still count as the latest
            late = {i: vw for i, vw in self.cmds.pop(kk).items() if kk > self.held_k[i]}
            if late and kk in self.poses:  # (older than the hold: stale anyway)
                self._hold(kk, late)
        if got:
            self._hold(k, got)
        self.halted = self.stopped(k)
        self.integrate(np.where(self.halted[:, None], 0.0, self.held))
        return set(got)

    def _hold(self, k: int, cmds: dict[int, np.ndarray]) -> None:
        """Hold the commands (v, ω) of tick k (agent index -> row) as the robots' plant inputs."""
        rows = np.array(list(cmds), dtype=np.int64)
        vw = np.array([cmds[i] for i in rows.tolist()])
        theta, p = self.poses[k]
        self.held[rows] = self.plant_input(vw, theta[rows], rows)
        self.held_k[rows] = k
        self.planned_p[rows] = p[rows]

    def plant_input(self, vw: np.ndarray, theta: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The input these robots' plant holds over the step: the head point's velocity u = M(θ_k) [v, ω]
        (eq. 3) at the heading the agent planned from, the zero-order hold of u the in-process engine uses
        (unicycle.through_inputs). vw: (n, 2), theta: (n,), rows: (n,) agent indices -> (n, 2)."""
        return unicycle.head_velocity(vw[:, 0], vw[:, 1], theta, self.l[rows])

    def integrate(self, u: np.ndarray) -> None:
        """Move every robot over one step under its held input (N, 2) (zeros: stopped)."""
        w = self.s.world
        self.p, self.theta = unicycle.step(self.p, self.theta, u, self.l, self.s.meta.dt_s, w.max_speed_mps,
                                           w.max_turn_rate_radps)

    def converged(self, alive: set[int]) -> bool:
        """Every live agent's head point within the planner's tolerance of its slot."""
        live = [self.index[a] for a in alive]
        if not live:
            return False
        e = errors(self.p[live], np.asarray(self.s.target_m), self.s.offsets[live])
        return bool(e.max() <= self.s.planner.converge_tol_m)
