"""Remark 1: detect a stall and add a small perturbation so agents escape local minima.

A stall is little movement *and* little progress toward the slot over a window while far from it:
both below 10 % of what free motion under the attraction would achieve in that window. Sliding along
an obstacle face is movement, so it is not a stall; a chattering agent pinned against a face normal to
its path is. On a stall the agent draws a random direction from its own generator, seeded by
(scenario seed, agent id), and pushes that way at `perturbation_mps` for one window. Pure and batched.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry import norm2

Array = NDArray[np.float64]

PROGRESS_FRACTION = 0.1
LEADER_STREAM = 1  # the virtual leader's generator: entropy (seed, 0, 1); agents use (seed, id, 0)


def generator(seed: int, agent_id: int, stream: int = 0) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, agent_id, stream])))


@dataclass
class StallState:
    """Per-agent history over one window (rows = agents in the batch)."""

    hist_p: Array  # (N, W, 2) positions, ring buffer indexed by tick mod W
    hist_e: Array  # (N, W) error norms
    filled: NDArray[np.int64]  # (N,) ticks of history since the last reset
    pert: Array  # (N, 2) current perturbation
    hold: NDArray[np.int64]  # (N,) ticks left to apply it
    rngs: list[np.random.Generator]
    stalls: NDArray[np.int64]  # (N,) how many stalls each agent has had

    @staticmethod
    def create(n: int, window: int, rngs: list[np.random.Generator]) -> StallState:
        return StallState(np.zeros((n, window, 2)), np.zeros((n, window)), np.zeros(n, dtype=np.int64),
                          np.zeros((n, 2)), np.zeros(n, dtype=np.int64), rngs, np.zeros(n, dtype=np.int64))


def window_ticks(stall_window_s: float, dt_s: float) -> int:
    return max(2, round(stall_window_s / dt_s))


def stall_step(st: StallState, k: int, p: Array, e: Array, magnitude: float, k_att: float, r_c: float,
               tol: float, dt: float) -> Array:
    """Update the history with tick k and return this tick's perturbation (N, 2).

    p (N, 2) positions, e (N,) error norms. `magnitude` 0 disables (always zeros).
    """
    n, w = st.hist_e.shape
    if magnitude <= 0.0:
        return np.zeros((n, 2))
    slot = k % w
    active = st.hold > 0
    st.hold = np.where(active, st.hold - 1, 0)
    st.pert = np.where((st.hold > 0)[:, None], st.pert, 0.0)
    old_p = st.hist_p[:, slot].copy()
    old_e = st.hist_e[:, slot].copy()
    st.hist_p[:, slot] = p
    st.hist_e[:, slot] = e
    st.filled = np.where(active, 0, st.filled + 1)
    full = st.filled > w
    expected = np.minimum(k_att * old_e, r_c * k_att) * (w * dt)
    thresh = PROGRESS_FRACTION * expected
    moved = norm2(p - old_p)
    stalled = full & ~active & (moved < thresh) & ((old_e - e) < thresh) & (e > 4 * tol)
    for i in np.flatnonzero(stalled):
        ang = st.rngs[i].uniform(0.0, 2 * np.pi)
        st.pert[i] = (magnitude * np.cos(ang), magnitude * np.sin(ang))
        st.hold[i] = w
        st.filled[i] = 0
        st.stalls[i] += 1
    return st.pert.copy()
