"""The benchmark's virtual leader (Franzè et al., the paper's comparison): pure.

The leader v starts at the centroid of the agents' starts and moves toward p* under the same bounded
attraction, repelled by every obstacle the swarm knows as if it were a body of radius R_c
(d_min = R_c + d_safe, d_max = R_c + d_max), at most at the cruise speed R_c k_att, with Remark 1's
stall perturbation. It reacts to the union of all agents' knowledge at the previous tick, which every
agent can compute from the shared obstacle sets, so each agent's copy of the leader is the same.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import Edges, norm2
from reconswarm.paper.deadlock import LEADER_STREAM, StallState, generator, stall_step, window_ticks
from reconswarm.paper.knowledge import obstacle_view
from reconswarm.paper.planner import attraction, obstacle_repulsion
from reconswarm.scenario.model import PlannerConfig, Scenario

Array = NDArray[np.float64]


class VirtualLeader:
    def __init__(self, s: Scenario) -> None:
        self.cfg: PlannerConfig = s.planner
        self.dt = s.meta.dt_s
        self.target = np.asarray(s.target_m, dtype=np.float64)
        self.v = s.starts.mean(axis=0).reshape(1, 2)  # (1, 2)
        self.velocity = np.zeros((1, 2))
        w = window_ticks(s.planner.stall_window_s, s.meta.dt_s)
        self.stall = StallState.create(1, w, [generator(s.meta.seed, 0, LEADER_STREAM)])

    def step(self, k: int, hulls: list[Array]) -> tuple[Array, Array]:
        """Leader position and velocity at tick k, both (1, 2); then advance to k+1.

        hulls: the swarm's known obstacle hulls at tick k-1, in increasing obstacle id.
        """
        c = self.cfg
        v = self.v
        u = attraction(v, self.target, np.zeros((1, 2)), c.k_att, c.target_radius_m)
        m = len(hulls)
        view = obstacle_view(v, 1, m, np.zeros(m, dtype=np.int64), np.arange(m), Edges.of(hulls))
        body = np.array([c.target_radius_m])
        rep = obstacle_repulsion(body, view.d, view.n, view.valid, c.d_safe_m, c.d_max_m, c.psi_mps)
        u = u + rep
        err = norm2(v - self.target)
        u = u + stall_step(self.stall, k, v, err, c.perturbation_mps, c.k_att, c.target_radius_m,
                           c.converge_tol_m, self.dt, rep)
        cap = c.target_radius_m * c.k_att
        speed = float(norm2(u)[0])
        if speed > cap:
            u = u * (cap / speed)
        pos, vel = v.copy(), u
        self.v = v + u * self.dt
        self.velocity = vel
        return pos, vel
