"""What a scenario may ask for: limits checked when a file is loaded, and warnings from the physics.

Refusals (the loader raises them as `FILE: field.path: what is wrong`, exit 2), each for a reason:

- **Magnitudes that make the program fail** (`problems`, every mode): float64 arithmetic that overflows or
  loses the resolution the geometry relies on, and memory fixed by the scenario's size (contour samples,
  the tables of every agent against every obstacle, the stall detector's history).
- **Discrete-time stability** of the control law, where a violation makes positions grow without bound.
- **The wire must carry every message the run can produce** (`wire_problems`, only where a wire is used: the
  distributed run's processes and `launch`; the in-process `sim` has none). Counts, lengths and ids against the
  wire's limits (reconswarm/scenario/wire_limits.py, which reconswarm/net/wire/wire.py's decoders enforce), and the
  encoded size of the largest message of each kind this scenario can produce (tests check these sizes against
  the wire's own encoder, byte for byte): whatever the wire would drop in the distributed run is refused
  there first.

Obstacle knowledge is not refused up front: it grows with what the agents know (a block of bits per agent
and obstacle it knows, reconswarm/paper/swarm_knowledge.py), at most a bit per contour sample per agent.

Warnings (`physics_warnings`): conditions derived from the control law (docs/paper.md, eqs. 9 and 11) that
a collision-free run needs. The run goes on without them, but contacts are to be expected.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import SAMPLE_SPACING_M, edge_sample_counts, norm2
from reconswarm.scenario.wire_limits import (
    MAX_IDS,
    MAX_OBSTACLES,
    MAX_PAYLOAD_BYTES,
    MAX_POINTS,
    MAX_REASON,
    MAX_STATS,
    MAX_STR,
    MAX_VERTICES,
)

# reconswarm.scenario.model's Scenario and ObstacleSpec: not imported, as the loader in that module calls this one.
Scenario = Any
ObstacleSpec = Any

# Coordinates and lengths within ±1,000 km. float64 resolves 1.2e-10 m there: nine orders below the 1 m
# contour spacing, so contour samples along an edge stay collinear within geometry.COLLINEAR_TOL (1e-9
# relative) and an agent's hull of an obstacle keeps at most two samples per edge (used below); squares
# of distances (1e12 m²) are far from overflow. Nothing a robot does needs more.
COORD_MAX_M = 1e6
# No speed may carry a robot farther than the whole coordinate range in one step: the next step's
# distances would be meaningless (and, a few steps on, not finite).
STEP_MAX_M = COORD_MAX_M
# Memory of the tables that grow with the scenario, each (agent x obstacle tables, stall history): 1 GiB.
TABLE_BUDGET_BYTES = 1 << 30
# Contour samples of all obstacles (every one is a candidate in every scan): 24 bytes each in the world,
# and at most a bit per agent in the knowledge tables. 200,000 samples = 200 km of obstacle boundary.
MAX_CONTOUR_SAMPLES = 200_000
_STALL_BYTES_PER_TICK = 3 * 8  # deadlock.StallState: a position (2 float64) and an error norm per tick
# Per agent and obstacle, the in-process engine keeps: its true distance (float64), its row in the knowledge
# blocks (int32), whether it knows it (bool), its cached hull (an object reference), and the reach mask (bool).
_AGENT_OBSTACLE_BYTES = 8 + 4 + 1 + 8 + 1

Problem = tuple[str, str]  # (field path, what is wrong)


def check_point(where: str, k: int, value: float, fail: Callable[[str, str], Exception]) -> None:
    """A coordinate in metres: within ±COORD_MAX_M."""
    if abs(value) > COORD_MAX_M:
        raise fail(f"{where}[{k}]", f"must be within ±{COORD_MAX_M:g} m, got {value}")


def problems(s: Scenario, agent_path: dict[int, str], obstacle_path: dict[str, str]) -> Iterator[Problem]:
    """What is wrong with a parsed scenario in any mode, cheapest checks first (the loader reports the first).

    agent_path / obstacle_path: id -> its table's path in the file (`agents[3]`, `obstacles[0]`).
    """
    yield from _magnitudes(s, agent_path)
    yield from _stability(s)
    yield from _memory(s, obstacle_path)


def wire_problems(s: Scenario, obstacle_path: dict[str, str]) -> Iterator[Problem]:
    """What the wire cannot carry of this scenario (where a wire is used: the distributed run, launch)."""
    yield from _wire(s, obstacle_path)


def _magnitudes(s: Scenario, agent_path: dict[int, str]) -> Iterator[Problem]:
    p = s.planner
    for key in ("target_radius_m", "d_safe_m", "d_max_m", "sensing_range_m", "link_range_m", "converge_tol_m"):
        v = getattr(p, key)
        if v > COORD_MAX_M:
            yield f"planner.{key}", f"must be at most {COORD_MAX_M:g} m, got {v}"
    for a in s.agents:
        for key in ("radius_m", "head_offset_m"):
            v = getattr(a, key)
            if v > COORD_MAX_M:
                yield f"{agent_path[a.id]}.{key}", f"must be at most {COORD_MAX_M:g} m, got {v}"
        # The body's turn rate is ω = u⊥ / head_offset_m: for the fastest step allowed (STEP_MAX_M per dt_s) it
        # must be finite, or the robot's heading is not (a normal offset of 1e-302 m overflows it at 2e7 m/s).
        if not math.isfinite(STEP_MAX_M / s.meta.dt_s / a.head_offset_m):
            yield f"{agent_path[a.id]}.head_offset_m", (
                f"must be at least {STEP_MAX_M / s.meta.dt_s / sys.float_info.max:.6g} m (the turn rate of a step of "
                f"{STEP_MAX_M:g} m, |u| / head_offset_m, must be finite), got {a.head_offset_m!r}")
        # A heading is an angle: beyond a few turns float64 keeps no useful fraction of a turn (at 1e16 rad
        # consecutive values are 2 rad apart).
        if abs(a.heading_rad) > 1000 * math.pi:
            yield f"{agent_path[a.id]}.heading_rad", f"must be within ±1000π rad, got {a.heading_rad}"


def _stability(s: Scenario) -> Iterator[Problem]:
    p, dt = s.planner, s.meta.dt_s
    # Attraction inside the target disk (eq. 9 with R_i* = R_c) is ė = -k_att e; explicit Euler gives
    # e(k+1) = (1 - k_att dt) e(k). With k_att dt >= 2 the tracking error grows every step, geometrically,
    # until positions overflow. (Outside the disk the speed is R_c k_att, so a step is < 2 R_c: finite.)
    if p.k_att * dt >= 2.0:
        yield "planner.k_att", (f"k_att * dt_s = {p.k_att * dt:.6g} must be below 2: inside the target disk each "
                                f"step multiplies the tracking error by |1 - k_att dt| >= 1 (explicit Euler on "
                                f"de/dt = -k_att e diverges)")
    if p.perturbation_mps * dt > STEP_MAX_M:
        yield "planner.perturbation_mps", (f"perturbation_mps * dt_s = {p.perturbation_mps * dt:.6g} m per step, "
                                           f"more than {STEP_MAX_M:g} m")
    # Repulsion (eq. 11) is |Ψ| (d_max,ij - d) / (d_max - d_safe): |Ψ| at d_min and, as the line goes on
    # below d_min, |Ψ| d_max,ij / (d_max - d_safe) when two head points meet. That speed for one step must
    # stay within STEP_MAX_M, or a single contact throws robots out of any meaningful range (a band of
    # 2e-15 m threw them 4.6e14 m). Written to stay finite for any finite inputs.
    band = p.d_max_m - p.d_safe_m
    reach = 2 * max(a.radius_m for a in s.agents) + p.d_max_m  # the largest d_max,ij
    psi_step = abs(p.psi_mps) * dt
    if psi_step > STEP_MAX_M:
        yield "planner.psi_mps", f"|psi_mps| * dt_s = {psi_step:.6g} m per step, more than {STEP_MAX_M:g} m"
    elif psi_step > STEP_MAX_M * (band / reach):
        yield "planner.d_safe_m", (f"the repulsion band d_max_m - d_safe_m = {band:.6g} m is too narrow for "
                                   f"psi_mps: at contact one step of repulsion, |Ψ| dt (d_max,ij / band) = "
                                   f"{psi_step / band * reach:.6g} m, would exceed {STEP_MAX_M:g} m")
    ticks = s.planner.stall_window_s / dt
    need = ticks * len(s.agents) * _STALL_BYTES_PER_TICK
    if need > TABLE_BUDGET_BYTES:
        yield "planner.stall_window_s", (f"the stall detector keeps stall_window_s / dt_s = {ticks:.4g} positions per "
                                         f"agent, {_size(need)} for {len(s.agents)} agents, over "
                                         f"{_size(TABLE_BUDGET_BYTES)}")


def _memory(s: Scenario, obstacle_path: dict[str, str]) -> Iterator[Problem]:
    total = 0
    for o in s.obstacles:
        total += sum(edge_sample_counts(_verts(o)))
        if total > MAX_CONTOUR_SAMPLES:
            yield f"{obstacle_path[o.id]}.vertices_m", (
                f"the obstacles' contours, sampled every {SAMPLE_SPACING_M:g} m, reach {total} points here, more "
                f"than {MAX_CONTOUR_SAMPLES} (obstacle boundaries longer than {MAX_CONTOUR_SAMPLES:,} m in all)")
            return
    # The tables of every agent against every obstacle (distances, knowledge rows, hulls).
    need = len(s.agents) * len(s.obstacles) * _AGENT_OBSTACLE_BYTES
    if need > TABLE_BUDGET_BYTES:
        yield "obstacles", (f"{len(s.agents)} agents x {len(s.obstacles)} obstacles need {_size(need)} of "
                            f"per-agent obstacle tables, over {_size(TABLE_BUDGET_BYTES)}")


# ------------------------------------------------------------------------------------------------ wire


def _wire(s: Scenario, obstacle_path: dict[str, str]) -> Iterator[Problem]:
    n = len(s.agents)
    if n > MAX_IDS:
        yield "agents", f"{n} agents, more than the wire's {MAX_IDS} per message"
        return
    for o in s.obstacles:
        if len(o.id) > MAX_STR:
            yield f"{obstacle_path[o.id]}.id", (f"{len(o.id)} characters, more than the wire's {MAX_STR} "
                                                f"(every scan point and shared hull carries the id)")
            return
    if len(s.obstacles) > MAX_OBSTACLES:
        yield "obstacles", f"{len(s.obstacles)} obstacles, more than the wire's {MAX_OBSTACLES} per obstacle set"
        return
    hull = {o.id: hull_vertices_max(o) for o in s.obstacles}
    for o in s.obstacles:
        if hull[o.id] > MAX_VERTICES:
            yield f"{obstacle_path[o.id]}.vertices_m", (
                f"an agent's hull of this obstacle can have up to {hull[o.id]} vertices (its contour samples), "
                f"more than the wire's {MAX_VERTICES}")
            return
    r_v = s.planner.sensing_range_m
    scan = {o.id: scan_points_max(o, r_v) for o in s.obstacles}
    if sum(scan.values()) > MAX_POINTS:
        yield "planner.sensing_range_m", (f"a scan within {r_v:g} m can hold up to {sum(scan.values())} contour "
                                          f"points of these obstacles, more than the wire's {MAX_POINTS}")
        return
    for path, what, size in largest_messages(s, scan, hull):
        if size > MAX_PAYLOAD_BYTES:
            yield path, (f"the largest {what} message of this scenario would be {size:,} bytes, over the wire's "
                         f"limit of {MAX_PAYLOAD_BYTES:,}")
            return


# msgpack sizes (the format's rules, as msgpack-python packs Python values): every float is a float64.
_FLOAT = 9


def _uint(v: int) -> int:
    return 1 if v < 128 else 2 if v < 256 else 3 if v < 65536 else 5 if v < 2**32 else 9


def _strlen(n: int) -> int:
    return n + (1 if n < 32 else 2 if n < 256 else 3 if n < 65536 else 5)


def _container(n: int) -> int:  # array or map header
    return 1 if n < 16 else 3 if n < 65536 else 5


def _keys(*names: str) -> int:  # a map of these keys: header and key strings ("v" included)
    return _container(len(names) + 1) + _strlen(1) + 1 + sum(_strlen(len(k)) for k in names)


def largest_messages(s: Scenario, scan: dict[str, int], hull: dict[str, int]) -> list[tuple[str, str, int]]:
    """(field path, message, encoded bytes) of the largest message of each growing kind this scenario can
    produce, as reconswarm.net.wire.wire encodes it (tests check these sizes against its encoder, byte for byte).

    Worst values where the scenario leaves them open: tick k and time at the end of the duration, counters
    (rev, rejected) at 2^53, the longest end reason and MAX_STATS statistics of the longest keys, the event
    that splits the whole swarm into single agents with every optional field (kind and cause of MAX_STR).
    Cmd and beacon have a fixed size (< 200 bytes); the state grows with its scan (counted with every other robot
    held near the agent: a bound, smaller than the truth's share per robot).
    """
    ids = [a.id for a in s.agents]
    n, a_max = len(ids), max(ids)
    k = _uint(round(s.meta.duration_s / s.meta.dt_s) + 1)
    id_bytes = sum(_uint(i) for i in ids)
    counter = _uint(2**53)
    truth = (_keys("k", "t", "ids", "x", "y", "theta", "px", "py") + k + _FLOAT + _container(n) + id_bytes
             + 5 * (_container(n) + n * _FLOAT))
    clock = (_keys("k", "t", "alive", "mode", "speed", "end", "reason", "rejected", "stats") + k + _FLOAT
             + _container(n) + id_bytes + _strlen(len("realtime")) + _FLOAT + 1 + _strlen(MAX_REASON) + counter
             + _container(MAX_STATS) + MAX_STATS * (_strlen(MAX_STR) + _FLOAT))
    # kind and cause at most MAX_STR characters; t_confirmed, duration_s, wall_unix floats
    event = (_keys("t", "kind", "before", "after", "agent", "cause", "t_confirmed", "duration_s", "wall_unix")
             + _FLOAT + _strlen(MAX_STR) + _container(1) + _container(n) + id_bytes + _container(n)
             + n * _container(1) + id_bytes + _uint(a_max) + _strlen(MAX_STR) + 3 * _FLOAT)
    # An agent's state with its scan: every contour point in range, every other robot held nearby.
    points, others = sum(scan.values()), [i for i in ids if i != a_max]
    state_b = (_keys("id", "k", "t", "x", "y", "theta", "px", "py", "points", *(["bodies"] if others else []))
               + _uint(a_max) + k + 6 * _FLOAT + _container(points)
               + sum(c * (_container(3) + 2 * _FLOAT + _strlen(len(oid))) for oid, c in scan.items())
               + (_container(len(others)) + sum(_container(3) + _uint(i) + 2 * _FLOAT for i in others) if others
                  else 0))
    sets = (_keys("id", "k", "rev", "obstacles") + _uint(a_max) + k + counter + _container(len(hull))
            + sum(_strlen(len(oid)) + _container(h) + h * (_container(2) + 2 * _FLOAT) for oid, h in hull.items()))
    return [("agents", "truth", truth), ("agents", "clock", clock), ("agents", "event", event),
            ("planner.sensing_range_m", "state", state_b), ("obstacles", "obstacle set", sets)]


def hull_vertices_max(o: ObstacleSpec) -> int:
    """The most vertices an agent's hull of this obstacle can have.

    The hull is that of a subset of the obstacle's contour samples (what was sensed, merged). Samples
    strictly inside one edge are collinear with any two others of that edge and dropped, so at most two
    samples per edge are vertices (fewer than there are samples on a short polygon).
    """
    counts = edge_sample_counts(_verts(o))
    return min(sum(counts), 2 * len(counts))


def scan_points_max(o: ObstacleSpec, sensing_range_m: float) -> int:
    """The most contour samples of this obstacle one scan (a disk of radius R_v) can hold.

    Edge e of length L carries n = ceil(L / spacing) samples L / n apart; a disk meets its line in a chord
    of at most 2 R_v, which holds at most floor(2 R_v n / L) + 1 of them (+1 for rounding at the rim).
    """
    v = _verts(o)
    out = 0
    for i, n in enumerate(edge_sample_counts(v)):
        length = float(norm2(v[(i + 1) % len(v)] - v[i]))
        out += min(n, math.floor(2 * sensing_range_m * n / length) + 2)
    return out


def _verts(o: ObstacleSpec) -> NDArray[np.float64]:
    return np.array(o.vertices_m, dtype=np.float64)


def _size(n: float) -> str:
    return f"{n / 2**30:.3g} GiB" if n >= 2**30 else f"{n / 2**20:.3g} MiB"


# -------------------------------------------------------------------------------------------- warnings


def physics_warnings(s: Scenario) -> list[Problem]:
    """Conditions a collision-free run needs (derived below from eqs. 9 and 11); none holds a run back.

    v: the fastest an agent closes on anything before repulsion acts: the attraction's cruise speed
    R_c k_att (its largest magnitude, eq. 9) plus the deadlock perturbation. w = d_max - d_safe: the
    repulsion band. In the band, at depth x (x = 0 at d_max, x = w at d_min), repulsion is |Ψ| x / w.
    For an agent driving at v into a static obstacle, explicit Euler gives x(k+1) = x(k) + dt (v - |Ψ| x(k) / w):
    from x(k) in [0, x*] the next depth is at most max(v dt, x*) (linear in x(k)), with x* = v w / |Ψ| the
    depth where repulsion balances the approach, and from beyond x* it only decreases. So the deepest an
    agent gets is max(v dt, v w / |Ψ|); two agents closing on each other double the approach speed and
    the repulsion alike: max(2 v dt, v w / |Ψ|). Both must stay below w, d_min, with a margin (a crowd
    adds pushes the pairwise bound does not see): we warn beyond half the band.
    """
    p, dt = s.planner, s.meta.dt_s
    v = p.target_radius_m * p.k_att + p.perturbation_mps
    w = p.d_max_m - p.d_safe_m
    psi = abs(p.psi_mps)
    out: list[Problem] = []
    if 2 * v * dt > w / 2:
        out.append(("scenario.dt_s", f"two agents closing at 2 x {v:.4g} m/s (R_c k_att + perturbation) cover "
                                     f"{2 * v * dt:.4g} m in one step, more than half the repulsion band d_max - "
                                     f"d_safe = {w:.4g} m: they can cross it before repulsion acts (contacts likely)"))
    if v > psi / 2:
        out.append(("planner.psi_mps", f"|Ψ| = {psi:.4g} m/s cannot stop an agent moving at {v:.4g} m/s (R_c k_att + "
                                       f"perturbation) within half the repulsion band: repulsion balances the approach "
                                       f"{v * w / psi:.4g} m deep into the {w:.4g} m band (|Ψ| >= 2 v needed; contacts "
                                       f"likely)"))
    # Sensing: an obstacle must be known before the head point enters its repulsion band, r_i + d_max from
    # its surface, and within one more step. The nearest contour sample to the nearest surface point is at
    # most half a sample spacing along the edge, so detection is certain from d only if
    # sqrt(d^2 + (spacing / 2)^2) <= R_v.
    need = math.hypot(max(a.radius_m for a in s.agents) + p.d_max_m + v * dt, SAMPLE_SPACING_M / 2)
    if s.obstacles and p.sensing_range_m < need:
        out.append(("planner.sensing_range_m", f"{p.sensing_range_m:.4g} m is less than the {need:.4g} m an agent "
                                               f"needs to see an obstacle before it enters the repulsion band (r + "
                                               f"d_max + one step): it meets obstacles it does not know (contacts "
                                               f"likely)"))
    return out
