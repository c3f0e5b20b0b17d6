"""Remark 1: detect a stall and add a small perturbation so agents escape local minima.

A stall is little movement *and* little progress toward the slot over a window while far from it:
both below 10 % of what free motion under the attraction would achieve in that window. Sliding along
an obstacle face is movement, so it is not a stall; a chattering agent pinned against a face normal to
its path is.

On a stall the agent starts an escape episode: it adds `perturbation_mps` along the boundary of what
repels it (perpendicular to its current repulsion, a wall-following push that turns with the boundary),
in a direction (left or right) drawn from its own generator seeded by (scenario seed, agent id); with
nothing repelling it, in a random direction. The episode lasts until the tracking error has dropped
below its value at the start by 5 % + 1 m, or for at most ESCAPE_WINDOWS windows, after which it turns
round once for twice as long. Pure and batched; a run repeats exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import norm2

Array = NDArray[np.float64]

PROGRESS_FRACTION = 0.1
LEADER_STREAM = 1  # the virtual leader's generator: entropy (seed, 0, 1); agents use (seed, id, 0)


def generator(seed: int, agent_id: int, stream: int = 0) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, agent_id, stream])))


class Generators(Sequence[np.random.Generator]):
    """[generator(seed, id) for id in ids], each made when first read (a generator takes about 35 µs to
    make; only agents that stall read theirs): the same streams as the list."""

    def __init__(self, seed: int, ids: Sequence[int]) -> None:
        self.seed, self.ids = seed, [int(i) for i in ids]
        self._made: dict[int, np.random.Generator] = {}

    def __len__(self) -> int:
        return len(self.ids)

    @overload
    def __getitem__(self, k: int) -> np.random.Generator: ...

    @overload
    def __getitem__(self, k: slice) -> Sequence[np.random.Generator]: ...

    def __getitem__(self, k: int | slice) -> np.random.Generator | Sequence[np.random.Generator]:
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self.ids)))]
        k = int(k)
        g = self._made.get(k)
        if g is None:
            g = self._made[k] = generator(self.seed, self.ids[k])
        return g


@dataclass
class StallState:
    """Per-agent history over one window and the escape episode (rows = agents in the batch)."""

    hist_p: Array  # (W, N, 2) positions, ring buffer indexed by tick mod W (one tick's row contiguous)
    hist_e: Array  # (W, N) error norms
    filled: NDArray[np.int64]  # (N,) ticks of history since the last reset
    pert: Array  # (N, 2) current perturbation
    hold: NDArray[np.int64]  # (N,) ticks left in the current escape episode
    rngs: Sequence[np.random.Generator]
    stalls: NDArray[np.int64]  # (N,) how many stalls each agent has had
    side: Array  # (N,) +1 / -1: which way along the boundary; 0 outside an episode
    turned: NDArray[np.bool_]  # (N,) the episode has already turned round once
    e0: Array  # (N,) error when the episode started
    free_dir: Array  # (N, 2) direction when nothing repels

    @staticmethod
    def create(n: int, window: int, rngs: Sequence[np.random.Generator]) -> StallState:
        return StallState(np.zeros((window, n, 2)), np.zeros((window, n)), np.zeros(n, dtype=np.int64),
                          np.zeros((n, 2)), np.zeros(n, dtype=np.int64), rngs, np.zeros(n, dtype=np.int64),
                          np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n), np.zeros((n, 2)))


    @staticmethod
    def stack(states: list[StallState]) -> StallState:
        """Several states' rows as one (copies: write the rows back with `unstack`)."""
        cat = np.concatenate
        return StallState(cat([s.hist_p for s in states], axis=1), cat([s.hist_e for s in states], axis=1),
                          cat([s.filled for s in states]), cat([s.pert for s in states]),
                          cat([s.hold for s in states]), [g for s in states for g in s.rngs],
                          cat([s.stalls for s in states]), cat([s.side for s in states]),
                          cat([s.turned for s in states]), cat([s.e0 for s in states]),
                          cat([s.free_dir for s in states]))

    def unstack(self, states: list[StallState]) -> None:
        """Write this state's rows back into the states it was stacked from (in their order)."""
        at = 0
        for s in states:
            n = s.filled.shape[0]
            rows = slice(at, at + n)
            s.hist_p, s.hist_e = self.hist_p[:, rows], self.hist_e[:, rows]
            s.filled, s.pert, s.hold, s.stalls = self.filled[rows], self.pert[rows], self.hold[rows], self.stalls[rows]
            s.side, s.turned, s.e0, s.free_dir = self.side[rows], self.turned[rows], self.e0[rows], self.free_dir[rows]
            at += n


class StackedStalls:
    """Several agents' states stacked once and kept from one call to the next (an agent host's law, tick after
    tick, over the same agents): `take` stacks them only if they changed since `give_back` wrote the rows back
    (each state's fields are then views of the kept stack, so the stack is current: written in place through a
    view, it changed too; a field replaced by other code is no longer the view, and the states are stacked
    again)."""

    def __init__(self) -> None:
        self._states: list[StallState] = []
        self._views: list[tuple[object, ...]] = []  # each state's fields as `give_back` left them
        self._stacked: StallState | None = None

    def take(self, states: list[StallState]) -> StallState:
        """The states' rows as one (`StallState.stack`, or the kept stack while it is current)."""
        kept = self._stacked
        if kept is not None and len(states) == len(self._states) and all(
                s is t and _same(_fields(s), v) for s, t, v in zip(states, self._states, self._views, strict=True)):
            return kept
        return StallState.stack(states)

    def give_back(self, stacked: StallState, states: list[StallState]) -> None:
        """Write the rows back into the states (`unstack`) and keep the stack for the next `take`."""
        stacked.unstack(states)
        self._states, self._views, self._stacked = list(states), [_fields(s) for s in states], stacked


def _fields(s: StallState) -> tuple[object, ...]:
    return (s.hist_p, s.hist_e, s.filled, s.pert, s.hold, s.rngs, s.stalls, s.side, s.turned, s.e0, s.free_dir)


def _same(a: tuple[object, ...], b: tuple[object, ...]) -> bool:
    return all(x is y for x, y in zip(a, b, strict=True))


ESCAPE_WINDOWS = 6


def window_ticks(stall_window_s: float, dt_s: float) -> int:
    return max(2, round(stall_window_s / dt_s))


def stall_step(st: StallState, k: int, p: Array, e: Array, magnitude: float, k_att: float, r_c: float,
               tol: float, dt: float, push: Array | None = None) -> Array:
    """Update the history with tick k and return this tick's perturbation (N, 2).

    p (N, 2) positions, e (N,) error norms, push (N, 2) the repulsion acting on each agent now (the
    boundary to follow). `magnitude` 0 disables (always zeros).
    """
    w, n = st.hist_e.shape
    if magnitude <= 0.0:
        return np.zeros((n, 2))
    slot = k % w
    # Episodes in progress: end on progress, turn round once on timeout, else count down.
    active = st.side != 0.0
    if active.any():
        done = active & (e < st.e0 * 0.95 - 1.0)
        st.hold = np.where(active, st.hold - 1, 0)
        timeout = active & ~done & (st.hold <= 0)
        turn = timeout & ~st.turned
        st.side = np.where(turn, -st.side, st.side)
        st.turned = st.turned | turn
        st.hold = np.where(turn, 2 * ESCAPE_WINDOWS * w, st.hold)
        st.free_dir = np.where(turn[:, None], -st.free_dir, st.free_dir)
        ended = done | (timeout & ~turn)
        st.side = np.where(ended, 0.0, st.side)
        active = st.side != 0.0
    else:  # no episode: nothing ends or turns, and every countdown is 0
        st.hold = np.zeros_like(st.hold)
    old_p = st.hist_p[slot].copy()
    old_e = st.hist_e[slot].copy()
    st.hist_p[slot] = p
    st.hist_e[slot] = e
    st.filled = np.where(active, 0, st.filled + 1)
    full = st.filled > w
    expected = np.minimum(k_att * old_e, r_c * k_att) * (w * dt)
    thresh = PROGRESS_FRACTION * expected
    moved = norm2(p - old_p)
    stalled = full & ~active & (moved < thresh) & ((old_e - e) < thresh) & (e > 4 * tol)
    for i in stalled.nonzero()[0]:
        rng = st.rngs[i]
        st.side[i] = 1.0 if rng.uniform() < 0.5 else -1.0
        ang = rng.uniform(0.0, 2 * np.pi)
        st.free_dir[i] = (np.cos(ang), np.sin(ang))
        st.turned[i] = False
        st.e0[i] = e[i]
        st.hold[i] = ESCAPE_WINDOWS * w
        st.filled[i] = 0
        st.stalls[i] += 1
    active = st.side != 0.0
    if not active.any():
        st.pert = np.zeros((n, 2))
        return st.pert.copy()
    # Along the boundary: the repulsion turned by 90 degrees to the episode's side.
    if push is None:
        push = np.zeros((n, 2))
    mag = norm2(push)
    has = mag > 1e-9
    safe = np.where(has, mag, 1.0)
    tx = np.where(has, -push[:, 1] / safe * st.side, st.free_dir[:, 0])
    ty = np.where(has, push[:, 0] / safe * st.side, st.free_dir[:, 1])
    st.pert = np.where(active[:, None], magnitude * np.stack([tx, ty], axis=1), 0.0)
    return st.pert.copy()
