"""The ROS 2 mode plant step (body velocities held over the step) against a fine RK4 integration of eq. (1)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.plant.unicycle import body_centre, step_vw, wrap


def rk4_body(s: np.ndarray, th: np.ndarray, v: np.ndarray, w: np.ndarray, dt: float, n: int = 200):
    """Eq. (1): ṡ = v [cos θ, sin θ], θ̇ = ω, with v and ω constant, by RK4 at dt / n."""
    h = dt / n

    def f(s_, th_):
        return v[:, None] * np.stack([np.cos(th_), np.sin(th_)], axis=1), w

    for _ in range(n):
        k1 = f(s, th)
        k2 = f(s + h / 2 * k1[0], th + h / 2 * k1[1])
        k3 = f(s + h / 2 * k2[0], th + h / 2 * k2[1])
        k4 = f(s + h * k3[0], th + h * k3[1])
        s = s + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        th = th + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return s, th


coord = st.floats(-50, 50)


@settings(max_examples=30, deadline=None)
@given(coord, coord, st.floats(-3.2, 3.2), st.floats(-2, 2), st.floats(-3, 3), st.floats(0.05, 1.0))
def test_held_velocities_move_the_body_on_its_arc(x, y, th, v, w, l):
    p, theta, l_ = np.array([[x, y]]), np.array([th]), np.array([l])
    dt = 0.1
    p1, th1, v1, w1 = step_vw(p, theta, np.array([v]), np.array([w]), l_, dt)
    s_ref, th_ref = rk4_body(body_centre(p, theta, l_), theta, np.array([v]), np.array([w]), dt)
    assert np.allclose(body_centre(p1, th1, l_), s_ref, atol=1e-9)
    assert abs(wrap(th1 - th_ref)[0]) < 1e-9
    assert (v1[0], w1[0]) == (v, w)


def test_limits_saturate_the_applied_velocities():
    p, theta, l = np.zeros((3, 2)), np.zeros(3), np.full(3, 0.2)
    v, w = np.array([2.0, -2.0, 0.5]), np.array([-4.0, 0.1, 4.0])
    _, _, v1, w1 = step_vw(p, theta, v, w, l, 0.1, max_speed=1.0, max_turn_rate=1.5)
    assert v1.tolist() == [1.0, -1.0, 0.5] and w1.tolist() == [-1.5, 0.1, 1.5]
    p2, th2, _, _ = step_vw(p, theta, np.zeros(3), np.zeros(3), l, 0.1)
    assert np.array_equal(p2, p) and np.array_equal(th2, theta)
