"""Remark 1's stall detection and perturbation (reconswarm/paper/deadlock.py) and the benchmark's virtual leader."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reconswarm.paper.deadlock import ESCAPE_WINDOWS, StallState, generator, stall_step, window_ticks
from reconswarm.paper.leader import VirtualLeader
from reconswarm.scenario.model import AgentSpec, PlannerConfig, PlannerKind, Scenario, ScenarioMeta, WorldConfig

K_ATT, R_C, TOL, DT = 0.08, 80.0, 0.5, 0.05


def run_stall(positions: np.ndarray, errors: np.ndarray, magnitude: float = 1.0, seed: int = 0,
              ids=(1,), window_s: float = 5.0, push: np.ndarray | None = None):
    """Feed (T, N, 2) positions, (T, N) error norms and optionally (T, N, 2) repulsion; return per-tick
    perturbations (T, N, 2) and the state."""
    n = positions.shape[1]
    w = window_ticks(window_s, DT)
    st = StallState.create(n, w, [generator(seed, i) for i in ids])
    out = np.array([stall_step(st, k, positions[k], errors[k], magnitude, K_ATT, R_C, TOL, DT,
                               None if push is None else push[k])
                    for k in range(positions.shape[0])])
    return out, st, w


def first_draws(seed: int, agent_id: int) -> tuple[float, float]:
    """An episode's draws from the agent's own generator: its side, then a free direction."""
    g = generator(seed, agent_id)
    side = 1.0 if g.uniform() < 0.5 else -1.0
    return side, g.uniform(0.0, 2 * math.pi)


def test_window_ticks():
    assert window_ticks(5.0, 0.05) == 100
    assert window_ticks(0.05, 0.05) == 2  # at least two ticks


def test_pinned_agent_escape_episode_turns_round_once_then_ends():
    pos = np.zeros((1, 1, 2)) + np.array([300.0, 4.0])
    w = window_ticks(5.0, DT)
    t = w * (1 + ESCAPE_WINDOWS * 3 + 3)
    pert, st, w = run_stall(np.repeat(pos, t, axis=0), np.full((t, 1), 200.0), magnitude=1.5, seed=11, ids=(7,))
    mag = np.hypot(pert[..., 0], pert[..., 1])[:, 0]
    on = np.flatnonzero(mag > 0)
    first = int(on[0])
    assert w <= first <= w + 1  # needs a full window of history first
    # Nothing repels it: it pushes at perturbation_mps in the free direction drawn from its own generator...
    _, ang = first_draws(11, 7)
    np.testing.assert_allclose(pert[first, 0], [1.5 * math.cos(ang), 1.5 * math.sin(ang)], atol=1e-15)
    leg = ESCAPE_WINDOWS * w
    assert np.all(pert[first:first + leg] == pert[first])
    # ...with no progress it turns round once, for twice as long, then the episode ends.
    assert np.all(pert[first + leg:first + 3 * leg] == -pert[first])
    assert mag[first + 3 * leg] == 0.0
    # Still pinned: a new stall after another full window.
    again = on[on > first + 3 * leg]
    assert again.size and again[0] >= first + 3 * leg + w and st.stalls[0] == 2


def test_escape_follows_the_boundary_and_ends_on_progress():
    w = window_ticks(5.0, DT)
    t = 3 * w
    pos = np.zeros((t, 1, 2)) + np.array([300.0, 4.0])
    err = np.full((t, 1), 200.0)
    push = np.zeros((t, 1, 2)) + np.array([0.0, 10.0])  # a face below it pushes it up
    progress_at = 2 * w
    err[progress_at:] = 200.0 * 0.95 - 1.5  # below e0 * 0.95 - 1: the episode is over
    pert, _, _ = run_stall(pos, err, magnitude=2.0, seed=3, ids=(5,), push=push)
    on = np.flatnonzero(np.hypot(pert[:, 0, 0], pert[:, 0, 1]) > 0)
    side, _ = first_draws(3, 5)
    # Along the face (perpendicular to the push), to the side drawn for this episode.
    np.testing.assert_allclose(pert[on[0], 0], [-2.0 * side, 0.0], atol=1e-15)
    assert on[-1] == progress_at - 1 and np.all(pert[progress_at:] == 0.0)


def test_no_stall_when_moving_freely_sliding_or_close_to_the_slot_or_disabled():
    t = 400
    k = np.arange(t)[:, None]
    # Free motion toward the slot under the attraction (inside the disk: e decays as exp(-k_att t)).
    e0 = 60.0
    e = e0 * np.exp(-K_ATT * DT * k)
    free = np.concatenate([800.0 - e[..., None], np.zeros((t, 1, 1))], axis=2)
    assert not np.any(run_stall(free, e)[0])
    # Sliding along a face at 2 m/s with no progress: movement is not a stall.
    slide = np.concatenate([np.full((t, 1, 1), 300.0), 2.0 * DT * k[..., None]], axis=2)
    assert not np.any(run_stall(slide, np.full((t, 1), 150.0))[0])
    # Pinned but already within 4 tol of the slot: not a stall.
    assert not np.any(run_stall(np.zeros((t, 1, 2)), np.full((t, 1), 1.9))[0])
    # perturbation_mps = 0 disables it.
    assert not np.any(run_stall(np.zeros((t, 1, 2)), np.full((t, 1), 200.0), magnitude=0.0)[0])


def test_stall_perturbations_are_per_agent_and_reproducible():
    t = 250
    pos = np.zeros((t, 3, 2)) + np.array([[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]])
    err = np.full((t, 3), 300.0)
    a, _, _ = run_stall(pos, err, seed=4, ids=(1, 2, 3))
    b, _, _ = run_stall(pos, err, seed=4, ids=(1, 2, 3))
    c, _, _ = run_stall(pos, err, seed=5, ids=(1, 2, 3))
    assert np.array_equal(a, b)  # same (seed, id): same draws
    assert not np.array_equal(a, c)
    first = np.flatnonzero(np.hypot(*a[:, 0].T) > 0)[0]
    dirs = a[first]
    assert len({tuple(np.round(d, 12)) for d in dirs}) == 3  # each agent its own direction
    # An agent's row computed alone (agent process, N = 1) equals its row in the batch (engine).
    solo, _, _ = run_stall(pos[:, 1:2], err[:, 1:2], seed=4, ids=(2,))
    assert np.array_equal(solo[:, 0], a[:, 1])


# ------------------------------------------------------------------------------------------ leader


def leader_scenario(starts, perturbation: float = 0.0) -> Scenario:
    agents = tuple(AgentSpec(id=i + 1, start_m=(float(x), float(y)), radius_m=2.0, offset_m=(25.0 * i, 0.0))
                   for i, (x, y) in enumerate(starts))
    return Scenario(ScenarioMeta("lead", 3, 300.0, DT),
                    PlannerConfig(PlannerKind.VIRTUAL_LEADER, K_ATT, R_C, -65.0, 2.0, 10.0, 40.0, 40.0, perturbation),
                    WorldConfig(), (800.0, 100.0), agents, ())


def test_virtual_leader_without_obstacles_goes_straight_at_bounded_speed():
    s = leader_scenario([(0.0, 0.0), (30.0, 10.0), (-6.0, 20.0)])
    lead = VirtualLeader(s)
    np.testing.assert_allclose(lead.v, [[8.0, 10.0]])  # starts at the centroid of the starts
    target = np.array([800.0, 100.0])
    direction = (target - np.array([8.0, 10.0])) / np.linalg.norm(target - np.array([8.0, 10.0]))
    prev = None
    for k in range(6000):
        pos, vel = lead.step(k, [])
        speed = float(np.hypot(*vel[0]))
        assert speed <= R_C * K_ATT * (1 + 1e-12)  # at most the cruise speed R_c k_att
        if prev is not None:
            np.testing.assert_allclose(pos, prev[0] + prev[1] * DT, atol=1e-12)  # integrates its velocity
        rel = pos[0] - np.array([8.0, 10.0])
        assert abs(rel[0] * direction[1] - rel[1] * direction[0]) < 1e-8  # on the straight line to p*
        prev = (pos, vel)
    assert prev is not None and np.hypot(*(prev[0][0] - target)) < 1e-2  # and converges to p*


def test_virtual_leader_is_repelled_by_known_obstacles_as_a_body_of_radius_rc():
    s = leader_scenario([(0.0, 100.0)])
    lead = VirtualLeader(s)
    # A wall across the path, 85 m ahead: within R_c + d_max = 90 m of the leader.
    wall = np.array([[85.0, 0.0], [95.0, 0.0], [95.0, 200.0], [85.0, 200.0]])
    _, vel_free = VirtualLeader(s).step(0, [])
    _, vel = lead.step(0, [wall])
    assert vel_free[0, 0] == pytest.approx(R_C * K_ATT)
    assert vel[0, 0] < vel_free[0, 0] - 1.0  # slowed by the repulsion
    far = VirtualLeader(s)
    far_wall = wall + np.array([100.0, 0.0])
    _, vel_far = far.step(0, [far_wall])
    np.testing.assert_allclose(vel_far, vel_free)  # beyond R_c + d_max: no effect
