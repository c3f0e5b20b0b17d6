"""A sparse grid swarm for scaling benchmarks: each agent has about 8 neighbours within link range
whatever N is (spacing 25 m: the 4 side neighbours at 25 m and the 4 diagonal ones at 35.4 m are within
the 40 m link range, the next ring at 50 m is not). The slots are the starts translated by a common
shift, so the formation moves as a block and the neighbourhoods stay what they are."""

from __future__ import annotations

import math

import numpy as np

from reconswarm.scenario.model import AgentSpec, PlannerConfig, PlannerKind, Scenario, ScenarioMeta, WorldConfig

SPACING_M = 25.0


def grid_scenario(n: int, duration_s: float, shift_m: float = 60.0, seed: int = 0) -> Scenario:
    side = math.ceil(math.sqrt(n))
    xy = np.array([(SPACING_M * (i % side), SPACING_M * (i // side)) for i in range(n)], dtype=np.float64)
    centre = xy.mean(axis=0)
    offsets = np.round(xy - centre, 3)
    form_r = float(np.hypot(offsets[:, 0], offsets[:, 1]).max())
    agents = tuple(AgentSpec(id=i + 1, start_m=(float(xy[i, 0]), float(xy[i, 1])), heading_rad=0.0, radius_m=1.5,
                             offset_m=(float(offsets[i, 0]), float(offsets[i, 1])), head_offset_m=0.5)
                   for i in range(n))
    planner = PlannerConfig(kind=PlannerKind.RECONFIGURABLE, k_att=0.08, target_radius_m=max(80.0, form_r + 20.0),
                            psi_mps=-65.0, d_safe_m=2.0, d_max_m=10.0, sensing_range_m=40.0, link_range_m=40.0,
                            perturbation_mps=0.0, converge_tol_m=0.5)
    return Scenario(meta=ScenarioMeta(name=f"grid{n}", seed=seed, duration_s=duration_s, dt_s=0.05),
                    planner=planner, world=WorldConfig(), target_m=(float(centre[0] + shift_m), float(centre[1])),
                    agents=agents, obstacles=())
