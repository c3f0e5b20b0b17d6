"""The paper's control law (eqs. 7-11), pure and batched over agents. No zenoh, no I/O.

Sign convention (docs/paper.md): u_i = -(∇U_att + ∇U_rep^a + ∇U_rep^o) with Ψ < 0, so attraction pulls
toward the slot p* + Δ_i and repulsion pushes apart.

Every function takes arrays whose first axis is "the agents being computed" (N): the in-process engine
passes the whole swarm, an agent process passes itself (N = 1). Neighbours and obstacles come as padded
tables (N, K) in a canonical order (neighbour id, obstacle id) and are summed column by column, so one
agent's row is bit-identical whichever way it is computed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import norm2
from reconswarm.scenario.model import PlannerConfig

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]
_A = TypeVar("_A", Array, Mask)


def attraction(p: Array, center: Array, offset: Array, k_att: float, r_c: float) -> Array:
    """-∇U_att of eq. (9) for a circular target region (R_i* = R_c).

    p (N, 2), center (N, 2) or (2,), offset (N, 2) -> (N, 2).
    Inside B(center, R_c): -k_att e_i with e_i = p_i - (center + Δ_i) (R_c / R_i* = 1).
    Outside: constant magnitude R_c k_att toward the centre. At the switch the two branches differ by
    k_att Δ_i (the paper claims continuity; we keep its form and switch on ‖p - center‖ <= R_c).
    """
    rel = p - center  # (N, 2)
    dist = norm2(rel)  # (N,)
    inside = dist <= r_c
    e = rel - offset
    safe = np.where(dist > 0.0, dist, 1.0)
    out = -r_c * k_att * rel / safe[:, None]  # both columns at once, element by element as before
    return np.where(inside[:, None], -k_att * e, out)


def repulsion_speed(d: Array, d_min: Array, d_max: Array, psi: float, d_contact: Array) -> Array:
    """Magnitude of one repulsive term of eq. (11): -Ψ (d_max - d) / (d_max - d_min) for d <= d_max.

    |Ψ| at d = d_min, 0 at d_max, linear between and continuing upward below d_min down to contact
    (d = d_contact, the surface gap 0), where it stays: once in contact the push keeps its contact value
    |Ψ| (d_max - d_contact) / (d_max - d_min) instead of growing without bound. A run without contact
    (the paper's) is unchanged bit for bit. Shapes broadcast.
    """
    return np.where(d <= d_max, -psi * (d_max - np.maximum(d, d_contact)) / (d_max - d_min), 0.0)


def max_repulsion_speed(psi: float, d_safe: float, d_max: float) -> float:
    """The largest magnitude of one repulsive term: its contact value |Ψ| d_max / (d_max - d_safe)."""
    return -psi * d_max / (d_max - d_safe)


def _accumulate(tx: Array, ty: Array, valid: Mask) -> Array:
    """Sum the terms (tx, ty) (N, K) over K in column order, skipping invalid entries. -> (N, 2)

    The sum is sequential from zero, 0 + t_1 + t_2 + ... + t_K, whatever K (so one agent's row is the same
    bit for bit in a table of any width): for a few rows, one running sum (ufunc accumulate, sequential by
    definition) over a leading column of zeros; for many, K additions (numpy's accumulate over a short
    axis is slow), the same operations. The terms come as coordinate planes (N, K): built that way, the
    element-wise arithmetic is the same as on (N, K, 2) arrays and several times cheaper than broadcasting
    over a last axis of 2.
    """
    n, k = tx.shape
    if k == 0:
        return np.zeros((n, 2))
    terms = np.zeros((k + 1, n, 2))  # (1 + K, N, 2): zeros, then the valid terms (+0.0 where invalid)
    np.copyto(terms[1:, :, 0], tx.T, where=valid.T)
    np.copyto(terms[1:, :, 1], ty.T, where=valid.T)
    if n <= _FEW_ROWS:
        return np.add.accumulate(terms, axis=0)[k]
    acc = terms[0]
    for c in range(1, k + 1):
        acc = acc + terms[c]
    return acc


_FEW_ROWS = 64


def agent_repulsion(p: Array, r: Array, nb_p: Array, nb_r: Array, nb_valid: Mask,
                    d_safe: float, d_max: float, psi: float) -> Array:
    """-∇U_rep^a of eq. (11) over each agent's neighbour table.

    p (N, 2), r (N,), nb_p (N, K, 2), nb_r (N, K), nb_valid (N, K) -> (N, 2).
    A table entry beyond d_max,ij contributes nothing, so tables may hold more than N_i(t).
    """
    if nb_p.shape[1] == 0:  # no neighbour: the sum over no column
        return np.zeros((p.shape[0], 2))
    # p_i - p_j and its norm2, on coordinate planes (N, K)
    rx = p[:, 0:1] - nb_p[:, :, 0]
    ry = p[:, 1:2] - nb_p[:, :, 1]
    d = np.sqrt(rx * rx + ry * ry)
    rr = r[:, None] + nb_r
    dmin = rr + d_safe
    dmax = rr + d_max
    mag = repulsion_speed(d, dmin, dmax, psi, rr)
    pos = d > 0.0
    safe = np.where(pos, d, 1.0)
    # Coincident centres have no direction: push along +x (a measure-zero case, but never NaN).
    tx = mag * np.where(pos, rx / safe, 1.0)
    ty = mag * np.where(pos, ry / safe, 0.0)
    return _accumulate(tx, ty, nb_valid & (d <= dmax))


def obstacle_repulsion(r: Array, ob_d: Array, ob_n: Array, ob_valid: Mask,
                       d_safe: float, d_max: float, psi: float) -> Array:
    """-∇U_rep^o: the same form as (11) against the nearest point of each known obstacle.

    r (N,), ob_d (N, M) signed distance from p_i to the known hull, ob_n (N, M, 2) outward unit normal
    at the nearest point, ob_valid (N, M) -> (N, 2). d_min = r_i + d_safe, d_max = r_i + d_max.
    """
    if ob_d.shape[1] == 0:  # no obstacle: the sum over no column
        return np.zeros((ob_d.shape[0], 2))
    dmin = r[:, None] + d_safe
    dmax = r[:, None] + d_max
    mag = repulsion_speed(ob_d, dmin, dmax, psi, r[:, None])
    return _accumulate(mag * ob_n[:, :, 0], mag * ob_n[:, :, 1], ob_valid & (ob_d <= dmax))


def containment(p: Array, r: Array, center: Array, r_c: float, d_safe: float, d_max: float,
                psi: float) -> Array:
    """Virtual-leader benchmark: keep agents inside B(center, R_c) with the same linear wall.

    p (N, 2), r (N,), center (N, 2) -> (N, 2). The boundary acts only from inside; an agent pushed out
    is pulled back by the attraction (the paper's benchmark can lose agents for good; ours rejoin).
    """
    rel = center - p
    dist = norm2(rel)
    d = r_c - dist
    mag = repulsion_speed(d, r + d_safe, r + d_max, psi, r)
    mag = np.where(dist <= r_c, mag, 0.0)
    safe = np.where(dist > 0.0, dist, 1.0)
    return np.stack([mag * rel[:, 0] / safe, mag * rel[:, 1] / safe], axis=1)


@dataclass
class Neighbours:
    """Padded neighbour table, rows = computed agents, columns in increasing neighbour id."""

    p: Array  # (N, K, 2)
    r: Array  # (N, K)
    valid: Mask  # (N, K)

    @staticmethod
    def empty(n: int) -> Neighbours:
        """No neighbour for any of n rows (one table per n, shared: its arrays hold nothing and are read-only)."""
        return _empty_neighbours(n)

    @staticmethod
    def stack(tables: Sequence[Neighbours]) -> Neighbours:
        """Several tables' rows as one (sum N_t, max K_t), each padded with invalid columns (adding nothing)."""
        return Neighbours(*_stack_padded([(t.p, t.r, t.valid) for t in tables]))


@dataclass
class ObstacleView:
    """What each agent knows of the obstacles near it, columns in increasing obstacle id."""

    d: Array  # (N, M) signed distance to the known hull
    n: Array  # (N, M, 2) outward unit normal
    valid: Mask  # (N, M)

    @staticmethod
    def empty(n: int) -> ObstacleView:
        """No obstacle for any of n rows (one view per n, shared: its arrays hold nothing and are read-only)."""
        return _empty_view(n)

    @staticmethod
    def stack(views: Sequence[ObstacleView]) -> ObstacleView:
        """Several views' rows as one (sum N_v, max M_v), each padded with invalid columns (adding nothing)."""
        return ObstacleView(*_stack_padded([(v.d, v.n, v.valid) for v in views]))


def _read_only(a: _A) -> _A:
    a.flags.writeable = False
    return a


@lru_cache(maxsize=64)
def _empty_neighbours(n: int) -> Neighbours:
    return Neighbours(_read_only(np.zeros((n, 0, 2))), _read_only(np.zeros((n, 0))),
                      _read_only(np.zeros((n, 0), dtype=bool)))


@lru_cache(maxsize=64)
def _empty_view(n: int) -> ObstacleView:
    return ObstacleView(_read_only(np.zeros((n, 0))), _read_only(np.zeros((n, 0, 2))),
                        _read_only(np.zeros((n, 0), dtype=bool)))


def _stack_padded(parts: Sequence[tuple[Array, Array, Mask]]) -> tuple[Array, Array, Mask]:
    """Tables of the same fields (rows N_t, columns C_t, any trailing axes) as one: (sum N_t, max C_t, ...), the
    missing columns zeros (for the mask: False, so they add nothing). One width: concatenated as they are."""
    width = max(part[2].shape[1] for part in parts)
    if all(part[2].shape[1] == width for part in parts):
        a, b, c = (np.concatenate([part[f] for part in parts]) for f in range(3))
        return a, b, c
    n = sum(part[2].shape[0] for part in parts)
    out = tuple(np.zeros((n, width, *x.shape[2:]), dtype=x.dtype) for x in parts[0])
    at = 0
    for part in parts:
        rows, cols = part[2].shape
        for dst, src in zip(out, part, strict=True):
            dst[at:at + rows, :cols] = src
        at += rows
    return out[0], out[1], out[2]


def repulsion(cfg: PlannerConfig, p: Array, r: Array, nb: Neighbours, ob: ObstacleView) -> tuple[Array, Array]:
    """The two repulsive terms of eq. (7) for each agent: from neighbours and from known obstacles, (N, 2) each."""
    return (agent_repulsion(p, r, nb.p, nb.r, nb.valid, cfg.d_safe_m, cfg.d_max_m, cfg.psi_mps),
            obstacle_repulsion(r, ob.d, ob.n, ob.valid, cfg.d_safe_m, cfg.d_max_m, cfg.psi_mps))


def command(cfg: PlannerConfig, p: Array, r: Array, offset: Array, center: Array, nb: Neighbours,
            ob: ObstacleView, perturbation: Array, leader_velocity: Array | None = None,
            rep: tuple[Array, Array] | None = None) -> Array:
    """The head-point velocity u_i (N, 2) of eq. (7), plus Remark 1's perturbation.

    center (N, 2): p* for the reconfigurable planner, each agent's copy of the virtual leader for the
    benchmark (which also passes the leader's velocity as feed-forward and adds containment).
    rep: the terms of `repulsion` when the caller has them already.
    """
    rep_a, rep_o = rep if rep is not None else repulsion(cfg, p, r, nb, ob)
    u = attraction(p, center, offset, cfg.k_att, cfg.target_radius_m)
    u = u + rep_a
    u = u + rep_o
    if leader_velocity is not None:
        u = u + leader_velocity
        u = u + containment(p, r, center, cfg.target_radius_m, cfg.d_safe_m, cfg.d_max_m, cfg.psi_mps)
    return u + perturbation


def neighbour_table(p: Array, r: Array, pairs: NDArray[np.int64], d_max: float, d: Array | None = None) -> Neighbours:
    """Build every agent's table from candidate index pairs (i < j) over the whole swarm.

    p (N, 2), r (N,), pairs (E, 2), d (E,) the pairs' distances norm2(p[i] - p[j]) when the caller has
    them -> Neighbours with rows for all N agents, neighbours j sorted by index (the swarm is indexed in
    increasing id). Pairs beyond d_max,ij are dropped here.
    """
    return NeighbourTables()(p, r, pairs, d_max, d)


class NeighbourTables:
    """neighbour_table, call after call over one swarm (radii r fixed): the table's layout (which agent in
    which slot) depends only on the pairs within d_max,ij, which rarely change from one tick to the next,
    so it is kept while they stay the same and each call only places the positions."""

    def __init__(self) -> None:
        self._key = b""
        self._n = -1
        self._flat = np.zeros(0, dtype=np.int64)  # (2E',) slot of each entry in the flattened (N, K)
        self._dst = np.zeros(0, dtype=np.int64)  # (2E',) the neighbour in that slot
        self._k = 0
        self._nb_r = np.zeros((0, 0))  # (N, K), read-only
        self._valid = np.zeros((0, 0), dtype=bool)  # (N, K), read-only

    def __call__(self, p: Array, r: Array, pairs: NDArray[np.int64], d_max: float, d: Array | None = None
                 ) -> Neighbours:
        n = p.shape[0]
        if pairs.shape[0] == 0:
            return Neighbours.empty(n)
        i, j = pairs[:, 0], pairs[:, 1]
        if d is None:
            d = norm2(p[i] - p[j])
        at = (d <= r[i] + r[j] + d_max).nonzero()[0]
        if at.size == 0:
            return Neighbours.empty(n)
        i, j = i.take(at), j.take(at)
        key = i.tobytes() + j.tobytes()
        if n != self._n or key != self._key:
            self._layout(n, r, i, j)
            self._key, self._n = key, n
        k = self._k
        nb_p = np.zeros((n * k, 2))
        nb_p[self._flat] = p[self._dst]
        return Neighbours(nb_p.reshape(n, k, 2), self._nb_r, self._valid)

    def _layout(self, n: int, r: Array, i: NDArray[np.int64], j: NDArray[np.int64]) -> None:
        src = np.concatenate([i, j])  # (2E',) each pair in both directions
        dst = np.concatenate([j, i])
        order = np.lexsort((dst, src))
        src, dst = src[order], dst[order]
        counts = np.bincount(src, minlength=n)  # (N,)
        k = int(counts.max())
        starts = np.cumsum(counts) - counts
        flat = src * k + (np.arange(src.shape[0]) - starts[src])  # row-major slot of each entry in (N, K)
        nb_r = np.zeros(n * k)
        valid = np.zeros(n * k, dtype=bool)
        nb_r[flat] = r[dst]
        valid[flat] = True
        self._flat, self._dst, self._k = flat, dst, k
        self._nb_r, self._valid = nb_r.reshape(n, k), valid.reshape(n, k)
        self._nb_r.flags.writeable = False  # shared by every table of this layout
        self._valid.flags.writeable = False


def errors(p: Array, target: Array, offset: Array) -> Array:
    """Tracking error norms ‖p_i - (p* + Δ_i)‖: (N, 2), (2,), (N, 2) -> (N,)."""
    return norm2(p - (target + offset))
