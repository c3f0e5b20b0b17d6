"""Random valid scenarios of any size: `reconswarm scenario generate --agents N --obstacles M --seed S`.

Layout: starts on a jittered hexagonal lattice around the origin with spacing 2 r_max + d_max + 2 m
(Assumption 4.1 holds for every pair), the target formation the same lattice scaled up around
p* = (D, 0) (SLOT_SPACING_M between neighbouring slots, each agent keeping its place), and M random
convex polygons in the corridor between, apart from each other by more than the largest robot plus its
safety band and out of reach of the target slots (Assumption 4.2). The corridor is 2.5 times the swarm's width;
when it cannot hold M obstacles it grows by a quarter (up to GROWTHS times) and the target moves with it. The
planner's gains are the paper's; R_c grows with the formation so every slot lies well inside the target disk.

Why the formation is wider than the start: a filled lattice has interior slots, and an agent held up
behind an obstacle arrives after the agents around its slot have settled. It can only pass between two
settled neighbours if the gap between them clears both repulsion bands (eq. 11 acts within
r_i + r_j + d_max): a slot spacing of 2 (2 r_max + d_max) or more. At the start lattice's 22 m the
midpoint between two settled robots lies inside their safety bands (11 m < 2 r_max + d_safe = 12 m):
the late agent can only push one of them out of its slot, which then has to push the next, and the
stall perturbation (1 m/s) cannot win against repulsion of tens of m/s. The paper's own formation is a
ring (every slot on the outside), which never meets this.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from reconswarm.scenario.model import (
    AgentSpec,
    ObstacleSpec,
    PlannerConfig,
    PlannerKind,
    Scenario,
    ScenarioMeta,
    WorldConfig,
)

R_MIN_M, R_MAX_M = 2.5, 5.0
D_SAFE_M, D_MAX_M = 2.0, 10.0
CRUISE_MPS = 0.08 * 80.0  # the paper's R_c k_att
START_SPACING_M = 2 * R_MAX_M + D_MAX_M + 2.0
SLOT_SPACING_M = 2 * (2 * R_MAX_M + D_MAX_M) + 2.0  # a free lane between two settled neighbours
GROWTHS = 8  # how often the corridor may grow by a quarter when it cannot hold the obstacles asked for


def _hex_lattice(n: int, spacing: float) -> NDArray[np.float64]:
    """The n points of a hexagonal lattice closest to the origin, nearest first. -> (n, 2)"""
    k = math.ceil(math.sqrt(n / 2.5)) + 2
    while True:
        i, j = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1))
        pts = np.stack([(i + 0.5 * (j % 2)) * spacing, j * spacing * math.sqrt(3) / 2], axis=-1).reshape(-1, 2)
        d = np.hypot(pts[:, 0], pts[:, 1])
        if np.sum(d <= k * spacing * 0.8) >= n:
            order = np.lexsort((pts[:, 1], pts[:, 0], np.round(d, 9)))
            return pts[order][:n]
        k *= 2


def _convex_polygon(rng: np.random.Generator, centre: NDArray[np.float64], size: float) -> NDArray[np.float64]:
    """A strictly convex polygon: 3-7 points on an ellipse (an affine image of a circle), rotated."""
    k = int(rng.integers(3, 8))
    while True:
        ang = np.sort(rng.uniform(0, 2 * math.pi, k))
        gaps = np.diff(np.r_[ang, ang[0] + 2 * math.pi])
        if gaps.min() > 0.5 and gaps.max() < math.pi - 0.2:
            break
    a, b = size, size * rng.uniform(0.5, 1.0)
    rot = rng.uniform(0, math.pi)
    x, y = a * np.cos(ang), b * np.sin(ang)
    c, s = math.cos(rot), math.sin(rot)
    return np.round(np.stack([centre[0] + c * x - s * y, centre[1] + s * x + c * y], axis=1), 3)


def generate(n_agents: int, n_obstacles: int = 3, seed: int = 0, slot_spacing_m: float = SLOT_SPACING_M) -> Scenario:
    if n_agents < 1:
        raise ValueError("n_agents must be >= 1")
    if n_obstacles < 0:
        raise ValueError("n_obstacles must be >= 0")
    rng = np.random.default_rng(seed)
    radii = np.round(rng.uniform(R_MIN_M, R_MAX_M, n_agents), 2)
    lattice = _hex_lattice(n_agents, START_SPACING_M)
    # Each agent's slot keeps its place in the swarm (the start lattice scaled up at the target), so
    # nobody has to cross the formation: what the agents must solve is the obstacles, not the assignment.
    offsets = np.round(lattice * (slot_spacing_m / START_SPACING_M), 2)
    form_r = float(np.hypot(offsets[:, 0], offsets[:, 1]).max())
    swarm = np.round(lattice, 2)
    swarm_r = float(np.hypot(swarm[:, 0], swarm[:, 1]).max())  # the travelling swarm's extent
    r_c = max(80.0, math.ceil(form_r + R_MAX_M + D_MAX_M + 15.0))
    # Starts: the jittered lattice (spacing minus twice the jitter still clears r_i + r_j + d_safe).
    jitter = 3.0
    starts = np.round(lattice + rng.uniform(-jitter, jitter, (n_agents, 2)), 2)
    start_r = float(np.hypot(starts[:, 0], starts[:, 1]).max())
    width = max(100.0, swarm_r + 40.0)
    corridor = max(300.0, 2.5 * width)
    x0 = start_r + 60.0  # obstacles begin here
    obstacles: list[ObstacleSpec] = []
    placed: list[tuple[NDArray[np.float64], float]] = []
    clearance = 2 * R_MAX_M + D_MAX_M + 4.0  # wider than any robot plus both repulsion bands
    tries, longer = 0, 0
    while len(obstacles) < n_obstacles:
        tries += 1
        if tries > 20000:  # the corridor is full: it grows by a quarter, what it holds stays (a layout that fitted
            tries, longer, corridor = 0, longer + 1, corridor * 1.25  # is the same as it always was)
            if longer > GROWTHS:
                raise RuntimeError(f"could not place {n_obstacles} obstacles (placed {len(obstacles)})")
        size = rng.uniform(0.12, 0.3) * width
        centre = np.array([rng.uniform(x0 + size, x0 + corridor - size), rng.uniform(-width, width)])
        if any(float(np.hypot(*(centre - c))) < size + r + clearance for c, r in placed):
            continue
        poly = _convex_polygon(rng, centre, size)
        obstacles.append(ObstacleSpec(id=f"obs{len(obstacles):03d}", vertices_m=tuple(map(tuple, poly))))
        placed.append((centre, size))
    # The paper's cruise speed R_c k_att = 6.4 m/s whatever the size: a larger target disk lowers k_att rather
    # than speeding the swarm up (the pressure a crowd puts on an obstacle grows with the attraction).
    target_x = x0 + corridor + r_c + 60.0
    k_att = round(CRUISE_MPS / r_c, 6)
    travel = target_x / CRUISE_MPS
    settle = math.log(max(r_c, 1.0) / 0.5) / k_att
    # A generous limit (a run ends when it converges): detours, stalls and crowding at the slots take time.
    duration = math.ceil((2.5 * travel + 3.0 * settle) / 10.0) * 10.0
    return Scenario(
        meta=ScenarioMeta(name=f"gen-n{n_agents}-m{n_obstacles}-s{seed}", seed=seed, duration_s=duration, dt_s=0.05),
        planner=PlannerConfig(kind=PlannerKind.RECONFIGURABLE, k_att=k_att, target_radius_m=float(r_c), psi_mps=-65.0,
                              d_safe_m=D_SAFE_M, d_max_m=D_MAX_M, sensing_range_m=40.0, link_range_m=40.0,
                              perturbation_mps=1.0, converge_tol_m=0.5),
        world=WorldConfig(),
        target_m=(float(round(target_x, 2)), 0.0),
        agents=tuple(AgentSpec(id=i + 1, start_m=(float(starts[i, 0]), float(starts[i, 1])), radius_m=float(radii[i]),
                               offset_m=(float(offsets[i, 0]), float(offsets[i, 1]))) for i in range(n_agents)),
        obstacles=tuple(sorted(obstacles, key=lambda o: o.id)),
        source=f"<generated n={n_agents} m={n_obstacles} seed={seed}>",
    )
