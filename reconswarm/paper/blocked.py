"""Lost robots as obstacles: what the escape needs past a robot that died in the swarm's path.

A robot whose agent is gone stands still where it stopped: known, static and round. Beside a known
obstacle it makes a pocket that the paper's law cannot leave: attraction pulls an agent into the corner
between the obstacle's face and the dead robot, both repulsions push back, and the sum vanishes there
(a local minimum Remark 1 does not cover: it is made by a robot, not by the geometry the paper assumes).

The remedy keeps the law and changes what it is applied to: an agent treats a lost robot that is too
close to a known obstacle (or to another lost robot) for it to pass between them, as one convex obstacle
with them: the convex hull of the obstacle's known hull and the robot's disc. A convex obstacle has no
pocket, so the agent slides along it and round it as it does round any obstacle. "Too close to pass"
is a gap below `2 (r_i + d_max)`: between two repulsors closer than that the agent feels both at once,
and that is where the pocket forms. A lost robot alone, far from everything, stays a neighbour (one
disc makes no pocket).

Pure: hulls (V, 2) counter-clockwise, discs (L, 3) as (x, y, radius); no state, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import convex_hull, distance_to_polygon, norm2, points_inside_hull

Array = NDArray[np.float64]

DISC_SIDES = 16


def disc_polygon(x_m: float, y_m: float, radius_m: float, sides: int = DISC_SIDES) -> Array:
    """The regular polygon circumscribed about the disc (it holds the whole disc): (sides, 2), CCW."""
    a = np.arange(sides) * (2 * np.pi / sides)
    rr = radius_m / np.cos(np.pi / sides)
    return np.stack([x_m + rr * np.cos(a), y_m + rr * np.sin(a)], axis=1)


def pass_gap_m(radius_m: float, d_max_m: float) -> float:
    """The narrowest gap an agent of this radius passes without feeling both sides' repulsion at once."""
    return 2.0 * (radius_m + d_max_m)


@dataclass(frozen=True)
class Group:
    """Lost robots (disc indices) and known hulls (hull indices) too close to pass between, as one convex hull."""

    discs: tuple[int, ...]
    hulls: tuple[int, ...]
    hull: Array  # (V, 2) counter-clockwise


def lost_groups(hulls: list[Array], discs: Array, gap_m: float) -> list[Group]:
    """Group each lost robot's disc with the known hulls and the other discs closer to it than gap_m: the groups
    of two or more members with a disc in them, in the order of their first disc. hulls: M known hulls (V, 2);
    discs (L, 3). Hulls are never grouped with each other: only a lost robot joins things."""
    n_l, n_m = discs.shape[0], len(hulls)
    parent = list(range(n_l + n_m))  # union-find: discs 0..L-1, then hulls L..L+M-1

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def join(i: int, j: int) -> None:
        parent[root(i)] = root(j)

    c = discs[:, :2]  # (L, 2)
    for i in range(n_l):
        d = norm2(c[i + 1:] - c[i]) - discs[i + 1:, 2] - discs[i, 2]  # (L-i-1,) disc to disc gaps
        for j in np.flatnonzero(d < gap_m).tolist():
            join(i, i + 1 + j)
    for m, h in enumerate(hulls):
        if h.shape[0] == 0:
            continue
        if h.shape[0] < 3:  # a point or a segment: distance to its vertices and edge
            gap = _distance_to_degenerate(c, h) - discs[:, 2]
        else:
            gap = distance_to_polygon(c, h)[0] - discs[:, 2]  # (L,)
        for i in np.flatnonzero(gap < gap_m).tolist():
            join(i, n_l + m)
    members: dict[int, list[int]] = {}
    for i in range(n_l + n_m):
        members.setdefault(root(i), []).append(i)
    out = []
    for group in sorted(members.values(), key=min):
        if len(group) < 2 or min(group) >= n_l:  # alone, or hulls only (cannot happen: never joined)
            continue
        d_idx = tuple(i for i in group if i < n_l)
        h_idx = tuple(i - n_l for i in group if i >= n_l)
        pts = [disc_polygon(*discs[i].tolist()) for i in d_idx] + [hulls[m] for m in h_idx]
        out.append(Group(d_idx, h_idx, convex_hull(np.concatenate(pts))))
    return out


def inside(groups: list[Group], at: Array) -> tuple[int, ...]:
    """The groups whose hull holds the point `at` (2,) (an agent's head point; on its boundary counts)."""
    at = at.reshape(1, 2)
    return tuple(g for g, x in enumerate(groups) if points_inside_hull(at, x.hull)[0])


def blocked_hulls(hulls: list[Array], discs: Array, gap_m: float) -> tuple[list[Array], NDArray[np.bool_]]:
    """`merged_hulls` of every group `lost_groups` finds."""
    return merged_hulls(hulls, discs.shape[0], lost_groups(hulls, discs, gap_m))


def merged_hulls(hulls: list[Array], n_discs: int, groups: list[Group], apart: tuple[int, ...] = ()
                 ) -> tuple[list[Array], NDArray[np.bool_]]:
    """The hulls to plan with, and which of the n_discs lost robots went into them: every known hull in no
    merged group, in the given order, then each group's convex hull, in the groups' order; absorbed (L,): the
    discs in a merged group (the others stay neighbours).

    The groups in `apart` are not merged, their hulls as they are and their robots neighbours: those whose hull
    holds the planning agent's head point (`inside`). The merge keeps agents out of a pocket they would stick in;
    an agent the hull was made around (many robots counted lost at once, the swarm's own formation one group)
    would be pushed out of it at the repulsion's contact value (about 80 m/s in the paper), across whatever lies
    that way, the lost robots among them.
    """
    absorbed = np.zeros(n_discs, dtype=bool)
    merged: list[Array] = []
    grouped_hulls: set[int] = set()
    for g, x in enumerate(groups):
        if g in apart:
            continue
        absorbed[list(x.discs)] = True
        grouped_hulls.update(x.hulls)
        merged.append(x.hull)
    kept = [h for m, h in enumerate(hulls) if m not in grouped_hulls]
    return kept + merged, absorbed


def _distance_to_degenerate(c: Array, h: Array) -> Array:
    """Distance from points c (L, 2) to a point or segment h (1 or 2, 2)."""
    a, b = h[0], h[-1]
    ab = b - a
    den = float(ab @ ab)
    t = np.clip(((c - a) @ ab) / den, 0.0, 1.0) if den > 0 else np.zeros(c.shape[0])
    return norm2(c - (a + t[:, None] * ab))
