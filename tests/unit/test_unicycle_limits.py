"""Each actuator limit alone, and each at values below 1 (m/s, rad/s): a limit of 0 means none, a positive one
binds whatever its size, and one limit never clamps the other input. (Mutants of reconswarm/plant/unicycle.py
that survived the other tests: a speed limit of 0 read as "stand still", a turn-rate limit of 0 as "never
turn", limits of 1 or below ignored.)"""

from __future__ import annotations

import math

import numpy as np
import pytest

from reconswarm.plant.unicycle import body_centre, inputs, step, step_vw

L = np.array([0.5])
DT = 0.05


def _u(v: float, w: float, th: float) -> np.ndarray:
    """The head-point command whose inputs at heading th are (v, ω): u = M(θ) [v, ω] (eq. 3)."""
    c, s = math.cos(th), math.sin(th)
    return np.array([[c * v - L[0] * s * w, s * v + L[0] * c * w]])


@pytest.mark.parametrize("w_max", [0.5, 1.0, 3.0])
def test_a_turn_rate_limit_alone_leaves_the_speed_free(w_max: float) -> None:
    """u with (v, ω) = (4 m/s, 10 rad/s) at the start heading, |u| = 6.4 m/s at 0.896 rad from it; only ω
    limited. The asked ω = |u| sin(φ - θ) / l stays above 8.7 rad/s while θ turns by at most 0.15 rad, so ω is
    saturated throughout: θ turns by exactly ω_max dt. v = |u| cos(φ - θ) grows from 4 m/s toward 6.4 as θ
    turns toward u, and nothing limits it (a speed limit of 0 means none, not zero)."""
    p, th = np.array([[3.0, -2.0]]), np.array([0.4])
    u = _u(4.0, 10.0, 0.4)
    s0 = body_centre(p, th, L)
    p1, th1 = step(p, th, u, L, DT, max_speed=0.0, max_turn_rate=w_max)
    assert th1[0] - th[0] == pytest.approx(w_max * DT, rel=1e-9)
    travelled = float(np.hypot(*(body_centre(p1, th1, L) - s0)[0]))
    assert 4.0 * DT * (1 - 1e-9) < travelled < float(np.hypot(*u[0])) * DT


@pytest.mark.parametrize("v_max", [0.5, 1.0, 3.0])
def test_a_speed_limit_alone_leaves_the_turn_rate_free(v_max: float) -> None:
    """u with (v, ω) = (4 m/s, 2 rad/s) at the start heading, 0.245 rad from it; only v limited. v stays above
    3.9 m/s, so saturated: the body travels v_max dt (on an arc, its chord a hair shorter). The heading
    relaxes toward u at |u| / l = 8.2 /s, unlimited (a turn-rate limit of 0 means none): tan(ψ/2) decays as
    exp(-|u| t / l), so θ turns by 0.245 - 2 atan(tan(0.1225) exp(-0.41)) = 0.083 rad."""
    p, th = np.array([[3.0, -2.0]]), np.array([0.4])
    u = _u(4.0, 2.0, 0.4)
    s0 = body_centre(p, th, L)
    p1, th1 = step(p, th, u, L, DT, max_speed=v_max, max_turn_rate=0.0)
    travelled = float(np.hypot(*(body_centre(p1, th1, L) - s0)[0]))
    assert travelled == pytest.approx(v_max * DT, rel=1e-3)
    psi0 = math.atan2(1.0, 4.0)
    turn = psi0 - 2 * math.atan(math.tan(psi0 / 2) * math.exp(-float(np.hypot(*u[0])) / L[0] * DT))
    assert th1[0] - th[0] == pytest.approx(turn, rel=0.02)  # (10 held substeps of the exact relaxation)


@pytest.mark.parametrize("v_max", [0.2, 0.99, 1.0])
def test_a_speed_limit_of_1_or_less_binds_too(v_max: float) -> None:
    p, th = np.zeros((1, 2)), np.array([0.0])
    u = np.array([[30.0, 0.0]])  # straight ahead at 30 m/s
    s0 = body_centre(p, th, L)
    p1, th1 = step(p, th, u, L, DT, max_speed=v_max)
    np.testing.assert_allclose(body_centre(p1, th1, L) - s0, [[v_max * DT, 0.0]], atol=1e-12)


@pytest.mark.parametrize("w_max", [0.2, 0.99, 1.0])
def test_the_ros2_step_saturates_a_turn_rate_limit_of_1_or_less(w_max: float) -> None:
    p, th = np.array([[1.0, 1.0]]), np.array([0.0])
    _, th1, v1, w1 = step_vw(p, th, np.array([0.5]), np.array([2.0]), L, DT, max_turn_rate=w_max)
    assert (v1[0], w1[0]) == (0.5, w_max)
    assert th1[0] == pytest.approx(w_max * DT, rel=1e-12)
    _, _, v2, w2 = step_vw(p, th, np.array([3.0]), np.array([-2.0]), L, DT, max_speed=w_max, max_turn_rate=w_max)
    assert (v2[0], w2[0]) == (w_max, -w_max)


def test_inputs_of_the_commands_used_here() -> None:
    v, w = inputs(_u(4.0, 10.0, 0.4), np.array([0.4]), L)
    assert (v[0], w[0]) == (pytest.approx(4.0), pytest.approx(10.0))
