"""The ROS 2 mode plant step (body velocities held over the step) against a fine RK4 integration of eq. (1)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.plant.unicycle import arc_head_speed, arc_twist, body_centre, inputs, step_vw, wrap


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



@settings(max_examples=300, deadline=None)
@given(st.floats(-120, 120), st.floats(-120, 120), st.floats(-3.2, 3.2), st.floats(0.05, 2.0),
       st.sampled_from([0.01, 0.05, 0.1]))
def test_the_arc_twist_moves_the_head_point_by_exactly_u_dt(ux, uy, th, l, dt):
    """arc_twist: from the continuous (v, ω) = M(θ)⁻¹ u (eq. 3), the twist a base holds over dt (step_vw, checked
    against RK4 above) takes the head point to p + u dt at any heading; it turns at most half a turn; its head
    speed over the arc (arc_head_speed) is |u|; for |u| dt << l it is the continuous (v, ω)."""
    u, theta, l_ = np.array([[ux, uy]]), np.array([th]), np.array([l])
    p = np.array([[12.0, -7.0]])
    v0, w0 = inputs(u, theta, l_)
    v, w = arc_twist(float(v0[0]), float(w0[0]), l, dt)
    p1, _th1, _v, _w = step_vw(p, theta, np.array([v]), np.array([w]), l_, dt)
    assert np.abs(p1 - (p + u * dt)).max() <= 1e-9 * (1.0 + np.abs(u).max())
    assert abs(w) * dt <= np.pi * (1 + 1e-12)
    assert arc_head_speed(v, w, l, dt) == pytest.approx(np.hypot(ux, uy), rel=1e-9, abs=1e-9)
    small = 1e-9  # (|u| dt / l below 1e-6: the second-order terms, ~ |u| (|u| dt / l), vanish)
    vs, ws = arc_twist(small * float(v0[0]), small * float(w0[0]), l, dt)
    assert np.allclose([vs, ws], [small * v0[0], small * w0[0]], rtol=1e-4,
                       atol=1e-4 * small * float(np.hypot(ux, uy)) + 1e-300)


def test_the_arc_twist_in_the_cases_worked_by_hand():
    """Straight ahead: unchanged. Straight back by more than 2 l: reversing, no turn. Across at |u| dt = 2 l: a
    quarter-turn (a = 2 atan(Y / 2l) = π/2) with the body centre on a circle, the head point 1 m aside."""
    l, dt = 0.5, 0.05
    assert arc_twist(4.0, 0.0, l, dt) == (4.0, 0.0)
    assert arc_twist(-30.0, 0.0, l, dt) == (-30.0, 0.0)
    v, w = arc_twist(0.0, 20.0 / l, l, dt)  # u = 20 m/s across: Y = 1 m = 2 l
    assert w * dt == pytest.approx(np.pi / 2, abs=1e-12)
    p1, th1, _v, _w = step_vw(np.array([[0.5, 0.0]]), np.array([0.0]), np.array([v]), np.array([w]), np.array([l]), dt)
    assert np.allclose(p1, [[0.5, 1.0]], atol=1e-12) and th1[0] == pytest.approx(np.pi / 2)
    assert arc_head_speed(0.0, 2 * np.pi / dt, l, dt) == pytest.approx(0.0, abs=1e-9)  # a whole turn: back again
