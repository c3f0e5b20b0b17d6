"""Remark 1's stall rule (reconswarm/paper/deadlock.py) at its bounds: a stall is movement and progress over a
window both strictly below 10 % of what free motion under the attraction, min(k_att e, r_c k_att), would achieve
in it, while farther than 4 tol from the slot; an episode ends once the error is strictly below 95 % of its start
less 1 m; the perturbation follows the boundary at exactly `perturbation_mps`, to the side the agent drew."""

from __future__ import annotations

import numpy as np

from reconswarm.paper.deadlock import ESCAPE_WINDOWS, PROGRESS_FRACTION, window_ticks
from tests.unit.test_deadlock_leader import DT, K_ATT, R_C, TOL, first_draws, run_stall

W = window_ticks(5.0, DT)  # 100 ticks


def _threshold(e_m: float) -> float:
    """10 % of what free motion under the attraction achieves in a window from error e_m (the rule's words)."""
    return PROGRESS_FRACTION * (min(K_ATT * e_m, R_C * K_ATT) * (W * DT))


def _first_stall(pert: np.ndarray) -> int:
    on = np.flatnonzero(np.hypot(pert[:, 0, 0], pert[:, 0, 1]) > 0)
    return int(on[0]) if on.size else -1


def test_movement_of_exactly_the_threshold_is_not_a_stall() -> None:
    # Far from the slot (e = 200 m: the attraction at its cap r_c k_att), pinned except for one step at tick 1.
    # At tick W the window spans ticks 0..W: its movement is that step; at W + 1 the agent has not moved since.
    e = np.full((W + 3, 1), 200.0)
    for step_m, first in [(_threshold(200.0), W + 1), (np.nextafter(_threshold(200.0), 0.0), W)]:
        p = np.zeros((W + 3, 1, 2))
        p[1:, 0, 0] = step_m
        assert _first_stall(run_stall(p, e)[0]) == first


def test_progress_of_exactly_the_threshold_is_not_a_stall() -> None:
    # Pinned, the error dropping once at tick 1 (below the cap: from e = 50 m the threshold is 2 m, exactly).
    p = np.zeros((W + 3, 1, 2))
    assert _threshold(50.0) == 2.0
    for later_m, first in [(48.0, W + 1), (np.nextafter(48.0, np.inf), W)]:  # a drop of 2 m; a hair less
        e = np.full((W + 3, 1), 50.0)
        e[1:] = later_m
        assert _first_stall(run_stall(p, e)[0]) == first


def test_a_stall_only_farther_than_four_tolerances_from_the_slot() -> None:
    p = np.zeros((2 * W, 1, 2))
    assert _first_stall(run_stall(p, np.full((2 * W, 1), 4 * TOL))[0]) == -1  # at exactly 4 tol: close enough
    assert _first_stall(run_stall(p, np.full((2 * W, 1), 4.5 * TOL))[0]) == W
    assert _first_stall(run_stall(p, np.full((2 * W, 1), 5.0))[0]) == W


def test_an_episode_ends_once_the_error_is_strictly_below_95_percent_of_its_start_less_a_metre() -> None:
    t = 3 * W
    p = np.zeros((t, 1, 2))
    bound = 200.0 * 0.95 - 1.0
    for later_m, ends in [(bound, False), (190.5, False), (np.nextafter(bound, 0.0), True)]:
        e = np.full((t, 1), 200.0)
        e[W + 10:] = later_m
        pert, _, _ = run_stall(p, e)
        assert _first_stall(pert) == W
        assert bool(np.hypot(*pert[W + 10, 0]) == 0.0) == ends


def test_the_escape_runs_along_the_boundary_at_its_magnitude_to_each_agents_drawn_side() -> None:
    n, t = 40, W + 2
    p = np.zeros((t, n, 2)) + np.arange(n)[None, :, None] * 100.0
    push = np.zeros((t, n, 2)) + np.array([0.3, 0.4])  # a weak repulsion (0.5 m/s) from below left
    pert, st, _ = run_stall(p, np.full((t, n), 200.0), magnitude=1.5, ids=tuple(range(1, n + 1)), seed=9, push=push)
    sides = []
    for i in range(n):
        side, _ = first_draws(9, i + 1)  # the agent's own first draw decides its side
        sides.append(side)
        np.testing.assert_allclose(pert[W, i], 1.5 * side * np.array([-0.8, 0.6]), rtol=0, atol=1e-15)
    assert set(sides) == {1.0, -1.0} and st.side.tolist() == sides
    assert np.allclose(np.hypot(pert[W, :, 0], pert[W, :, 1]), 1.5)


def test_a_timed_out_episode_turns_to_the_other_side_of_the_boundary() -> None:
    leg = ESCAPE_WINDOWS * W
    t = W + leg + 2
    p = np.zeros((t, 1, 2))
    push = np.zeros((t, 1, 2)) + np.array([3.0, 4.0])
    pert, st, _ = run_stall(p, np.full((t, 1), 200.0), magnitude=2.0, ids=(3,), seed=1, push=push)
    first = pert[W, 0]
    np.testing.assert_allclose(np.abs(first), [1.6, 1.2], atol=1e-15)  # along (-4, 3) / 5, at 2 m/s
    assert np.array_equal(pert[W + leg - 1, 0], first)
    assert np.array_equal(pert[W + leg, 0], -first) and st.turned[0]


def test_disabled_it_neither_perturbs_nor_counts_stalls() -> None:
    p = np.zeros((3 * W, 1, 2))
    pert, st, _ = run_stall(p, np.full((3 * W, 1), 200.0), magnitude=0.0)
    assert not pert.any() and st.stalls[0] == 0
