"""The paper's law behind the seam: eq. (7) with Remark 1's escape, for the reconfigurable planner (centre p*)
and the virtual-leader benchmark (centre: each agent's copy of the leader, plus its velocity and containment)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from reconswarm.paper.deadlock import stall_step
from reconswarm.paper.planner import Neighbours, ObstacleView, command, errors, repulsion
from reconswarm.planners.seam import Tick
from reconswarm.scenario.model import PlannerConfig, Scenario

Array = NDArray[np.float64]


class PaperLaw:
    """Stateless: the stall history comes with the tick (its caller stacks the rows it computes)."""

    needs_tables = True
    needs_hulls = False

    def __init__(self, s: Scenario, ids: Sequence[int] | None = None) -> None:
        self.cfg: PlannerConfig = s.planner

    def command(self, t: Tick) -> Array:
        c, n = self.cfg, t.p.shape[0]
        nb = t.nb if t.nb is not None else Neighbours.empty(n)
        ob = t.ob if t.ob is not None else ObstacleView.empty(n)
        e = t.err if t.err is not None else errors(t.p, t.center, t.offset)
        rep = repulsion(c, t.p, t.r, nb, ob)
        pert = stall_step(t.stall, t.k, t.p, e, c.perturbation_mps, c.k_att, c.target_radius_m, c.converge_tol_m,
                          t.dt_s, rep[0] + rep[1])
        return command(c, t.p, t.r, t.offset, t.center, nb, ob, pert, t.lead_vel, rep)
