"""The unicycle world (eqs. 1-3) against a fine numerical integration of the unicycle itself.

The oracle integrates the body (s, θ) of eq. (1) with RK4 at a step hundreds of times finer than dt,
recomputing [v, ω] = M(θ)⁻¹ u at every stage (the continuous feedback linearisation), and reads the head
point from eq. (2). reconswarm.plant.unicycle.step must agree with it: without limits the head point moves by
exactly u dt and the heading follows its closed form.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.plant.unicycle import (
    SUBSTEPS,
    body_centre,
    head_point,
    head_velocity,
    inputs,
    step,
    through_inputs,
    wrap,
)

SETTINGS = settings(max_examples=60, deadline=None)


def unicycle_rhs(s: np.ndarray, th: np.ndarray, u: np.ndarray, l: np.ndarray,
                 v_max: float = 0.0, w_max: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (1) with [v, ω] = M(θ)⁻¹ u (eq. 3) written out independently, optionally saturated."""
    c, sn = np.cos(th), np.sin(th)
    v = u[:, 0] * c + u[:, 1] * sn
    w = (-u[:, 0] * sn + u[:, 1] * c) / l
    if v_max > 0:
        v = np.clip(v, -v_max, v_max)
    if w_max > 0:
        w = np.clip(w, -w_max, w_max)
    return np.stack([v * c, v * sn], axis=1), w


def rk4(s: np.ndarray, th: np.ndarray, u: np.ndarray, l: np.ndarray, dt: float, n: int,
        v_max: float = 0.0, w_max: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    # The heading relaxes at rate ‖u‖ / l: keep (rate * h) <= 0.005 so RK4 stays far below the tolerances.
    rate = float(np.max(np.hypot(u[:, 0], u[:, 1]) / l)) if u.size else 0.0
    n = max(n, math.ceil(rate * dt / 0.005))
    h = dt / n
    for _ in range(n):
        k1s, k1t = unicycle_rhs(s, th, u, l, v_max, w_max)
        k2s, k2t = unicycle_rhs(s + h / 2 * k1s, th + h / 2 * k1t, u, l, v_max, w_max)
        k3s, k3t = unicycle_rhs(s + h / 2 * k2s, th + h / 2 * k2t, u, l, v_max, w_max)
        k4s, k4t = unicycle_rhs(s + h * k3s, th + h * k3t, u, l, v_max, w_max)
        s = s + h / 6 * (k1s + 2 * k2s + 2 * k3s + k4s)
        th = th + h / 6 * (k1t + 2 * k2t + 2 * k3t + k4t)
    return s, th


def head(s: np.ndarray, th: np.ndarray, l: np.ndarray) -> np.ndarray:
    return s + l[:, None] * np.stack([np.cos(th), np.sin(th)], axis=1)


def angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(np.angle(np.exp(1j * (a - b))))


@st.composite
def robots(draw, n_max: int = 8):
    n = draw(st.integers(1, n_max))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    p = rng.uniform(-500, 500, (n, 2))
    th = rng.uniform(-math.pi, math.pi, n)
    speed = rng.uniform(0.0, draw(st.floats(0.1, 70.0)), n)
    phi = rng.uniform(-math.pi, math.pi, n)
    u = np.stack([speed * np.cos(phi), speed * np.sin(phi)], axis=1)
    l = rng.uniform(0.2, 2.0, n)
    dt = draw(st.sampled_from([0.01, 0.05, 0.1]))
    return p, th, u, l, dt


# ------------------------------------------------------------------------------------------ no limits


@SETTINGS
@given(robots())
def test_head_point_moves_by_exactly_u_dt(case):
    p, th, u, l, dt = case
    p1, _ = step(p, th, u, l, dt)
    assert np.array_equal(p1, p + u * dt)  # bit-exact (eq. 3 inverted: ṗ = u)


@SETTINGS
@given(robots())
def test_step_matches_fine_integration_of_the_unicycle(case):
    p, th, u, l, dt = case
    p1, th1 = step(p, th, u, l, dt)
    s_ref, th_ref = rk4(body_centre(p, th, l), th, u, l, dt, 400)
    p_ref = head(s_ref, th_ref, l)
    np.testing.assert_allclose(p1, p_ref, rtol=0, atol=1e-8)
    assert angle_diff(th1, th_ref).max() < 1e-8
    assert np.all((th1 > -math.pi) & (th1 <= math.pi))  # wrapped
    # s = p - l [cos θ, sin θ] of the new state is the integrated body centre.
    np.testing.assert_allclose(body_centre(p1, th1, l), s_ref, rtol=0, atol=1e-8)


def test_closed_loop_trajectory_matches_fine_integration():
    """Many steps of a zero-order-hold feedback u = -k (p - goal): step() vs RK4 of the body."""
    rng = np.random.default_rng(7)
    n, dt, steps = 6, 0.05, 300
    p = rng.uniform(-50, 50, (n, 2))
    th = rng.uniform(-math.pi, math.pi, n)
    l = rng.uniform(0.3, 1.0, n)
    goal = rng.uniform(-50, 50, (n, 2))
    s_ref, th_ref = body_centre(p, th, l), th.copy()
    for _ in range(steps):
        u = -0.5 * (p - goal) + np.array([1.0, -0.5])
        p, th = step(p, th, u, l, dt)
        u_ref = -0.5 * (head(s_ref, th_ref, l) - goal) + np.array([1.0, -0.5])
        s_ref, th_ref = rk4(s_ref, th_ref, u_ref, l, dt, 40)
    np.testing.assert_allclose(p, head(s_ref, th_ref, l), atol=1e-8)
    np.testing.assert_allclose(body_centre(p, th, l), s_ref, atol=1e-8)
    assert angle_diff(th, th_ref).max() < 1e-8


@SETTINGS
@given(robots())
def test_heading_converges_toward_u(case):
    p, th, u, l, dt = case
    speed = np.hypot(u[:, 0], u[:, 1])
    phi = np.arctan2(u[:, 1], u[:, 0])
    err = angle_diff(th, phi)
    for _ in range(200):
        p, th = step(p, th, u, l, dt)
        new = angle_diff(th, phi)
        # |θ - φ| never grows (ψ̇ = -(‖u‖/l) sin ψ) ...
        assert np.all(new <= err + 1e-12)
        err = new
    # ... and decays like tan(|ψ|/2) exp(-‖u‖ t / l): after 200 steps it is small where ‖u‖ t / l is large.
    moving = (speed * 200 * dt / l > 40) & (angle_diff(th, phi + math.pi) > 1e-3)
    assert np.all(err[moving] < 1e-6)


def test_zero_command_keeps_pose_and_inputs_invert_m():
    p = np.array([[1.0, 2.0]])
    th = np.array([0.7])
    l = np.array([0.5])
    p1, th1 = step(p, th, np.zeros((1, 2)), l, 0.05)
    assert np.array_equal(p1, p) and np.array_equal(th1, th)
    # inputs() is M(θ)⁻¹: M(θ) [v, ω] gives back u.
    rng = np.random.default_rng(0)
    for _ in range(20):
        u = rng.normal(size=(1, 2)) * 10
        t = rng.uniform(-4, 4, 1)
        v, w = inputs(u, t, l)
        m = np.array([[math.cos(t[0]), -l[0] * math.sin(t[0])], [math.sin(t[0]), l[0] * math.cos(t[0])]])
        np.testing.assert_allclose(m @ np.array([v[0], w[0]]), u[0], atol=1e-12)
        # head_velocity is M(θ) [v, ω] (eq. 3), row for row: what the world rebuilds from an agent's command
        np.testing.assert_allclose(head_velocity(v, w, t, l)[0], m @ np.array([v[0], w[0]]), atol=1e-12)
    # eq. (2) and the body centre are inverse maps.
    s = body_centre(p, th, l)
    np.testing.assert_allclose(head_point(s, th, l), p, atol=1e-15)
    assert wrap(np.array([math.pi]))[0] == pytest.approx(math.pi)
    assert wrap(np.array([-math.pi]))[0] == pytest.approx(math.pi)
    assert wrap(np.array([3 * math.pi / 2]))[0] == pytest.approx(-math.pi / 2)


# ------------------------------------------------------------------------------------------ limits


@SETTINGS
@given(robots(), st.floats(0.2, 10.0), st.floats(0.2, 5.0))
def test_limits_respected(case, v_max, w_max):
    p, th, u, l, dt = case
    for _ in range(20):
        s0 = body_centre(p, th, l)
        p1, th1 = step(p, th, u, l, dt, v_max, w_max)
        s1 = body_centre(p1, th1, l)
        # |v| <= v_max: the body travels at most v_max dt; |ω| <= ω_max: it turns at most ω_max dt.
        assert np.all(np.hypot(*(s1 - s0).T) <= v_max * dt * (1 + 1e-9))  # rounding of |s| ~ 1e3 only
        assert np.all(angle_diff(th1, th) <= w_max * dt * (1 + 1e-9) + 1e-12)
        p, th = p1, th1


def test_limits_only_speed_or_only_turn_rate():
    p = np.zeros((1, 2))
    th = np.array([0.0])
    l = np.array([0.5])
    u = np.array([[30.0, 0.0]])
    s0 = body_centre(p, th, l)
    p1, th1 = step(p, th, u, l, 0.05, max_speed=2.0)
    # Straight ahead at 30 m/s commanded, 2 m/s allowed: the head point lags u dt and moves 2 * 0.05 m.
    np.testing.assert_allclose(body_centre(p1, th1, l) - s0, [[0.1, 0.0]], atol=1e-12)
    assert p1[0, 0] < (p + u * 0.05)[0, 0]
    # Turning in place toward +y with only a turn-rate limit: θ advances by at most ω_max dt.
    _, th2 = step(p, th, np.array([[0.0, 5.0]]), l, 0.05, max_turn_rate=1.0)
    assert th2[0] == pytest.approx(0.05, rel=1e-12)


@settings(max_examples=25, deadline=None)
@given(robots(n_max=4), st.floats(0.5, 8.0), st.floats(0.5, 4.0))
def test_limited_step_matches_fine_integration_of_saturated_unicycle(case, v_max, w_max):
    """With limits the world integrates the saturated inputs; compare with a fine RK4 of the same ODE."""
    p, th, u, l, dt = case
    p1, th1 = step(p, th, u, l, dt, v_max, w_max)
    s_ref, th_ref = rk4(body_centre(p, th, l), th, u, l, dt, 400, v_max, w_max)
    # The world holds [v, ω] over 10 substeps of exact arcs: first-order in the substep, so compare to a
    # tolerance that scales with the motion over one substep.
    tol = 0.5 * (v_max + np.hypot(*u.T)) * dt / 10 * (w_max * dt) + 1e-9
    assert np.all(np.hypot(*(body_centre(p1, th1, l) - s_ref).T) <= tol * 4 + 1e-6)
    assert np.all(angle_diff(th1, th_ref) <= w_max * dt / 10 + 1e-9)


def held_substeps(s: np.ndarray, th: np.ndarray, u: np.ndarray, l: np.ndarray, dt: float, v_max: float,
                  w_max: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The world's model under limits, integrated numerically: over each of SUBSTEPS substeps of h = dt /
    SUBSTEPS, [v, ω] = sat(M(θ)⁻¹ u) at the substep's start is held, and ṡ = v [cos θ, sin θ], θ̇ = ω is
    integrated by RK4 with n steps of H = h / n. θ is linear in time, so RK4 is Simpson's rule on s: its
    error over dt is at most dt H⁴ |v| ω⁴ / 2880."""
    h = dt / SUBSTEPS
    big_h = h / n
    for _ in range(SUBSTEPS):
        c, sn = np.cos(th), np.sin(th)
        v = np.clip(u[:, 0] * c + u[:, 1] * sn, -v_max, v_max)
        w = np.clip((-u[:, 0] * sn + u[:, 1] * c) / l, -w_max, w_max)
        for _ in range(n):
            # k2 = k3: the right-hand side v [cos θ, sin θ] does not depend on s
            k1, k23, k4 = (np.stack([v * np.cos(a), v * np.sin(a)], axis=1)
                           for a in (th, th + big_h / 2 * w, th + big_h * w))
            s = s + big_h / 6 * (k1 + 4 * k23 + k4)
            th = th + big_h * w
    return s, th


@settings(max_examples=40, deadline=None)
@given(robots(n_max=4), st.floats(0.5, 8.0), st.floats(0.5, 4.0))
def test_limited_step_is_exact_arcs_of_the_held_substep_inputs(case, v_max, w_max):
    """Under limits each substep is the exact arc of its held (v, ω): against a fine RK4 of that same
    model, the difference is RK4's truncation (dt H⁴ v_max ω_max⁴ / 2880) plus rounding, not the model's
    first-order hold error (a chord along the substep's initial heading instead of the arc is off by about
    v ω h dt / 2, millions of times more)."""
    p, th, u, l, dt = case
    n = 8
    s_ref, th_ref = held_substeps(body_centre(p, th, l), th, u, l, dt, v_max, w_max, n)
    p1, th1 = step(p, th, u, l, dt, v_max, w_max)
    s1 = body_centre(p1, th1, l)
    truncation = dt * (dt / SUBSTEPS / n) ** 4 * v_max * w_max**4 / 2880
    # Rounding: |s| up to ~1e3 m, a few operations a step over SUBSTEPS (n + 1) steps of both integrations.
    rounding = 16 * np.finfo(float).eps * (1.0 + np.abs(s_ref).max(axis=1)) * SUBSTEPS * (n + 1)
    assert np.all(np.hypot(*(s1 - s_ref).T) <= 2 * truncation + rounding)
    assert np.all(angle_diff(th1, th_ref) <= 1e-12)


def test_limited_step_with_both_limits_binding_is_the_closed_form_circle():
    """u 45° off the heading and far above both limits: v = v_max and ω = ω_max throughout the step (the
    heading turns by 0.05 rad of the 0.785 it would need to unsaturate), so the body runs on the circle of
    radius v_max / ω_max: s(dt) = s0 + (v/ω) [sin(θ0 + ω dt) - sin θ0, cos θ0 - cos(θ0 + ω dt)]."""
    l = np.array([0.5, 1.5])
    th0 = np.array([0.3, -2.0])
    p = np.array([[10.0, -4.0], [-250.0, 300.0]])
    u = 100.0 * np.stack([np.cos(th0 + math.pi / 4), np.sin(th0 + math.pi / 4)], axis=1)
    v_max, w_max, dt = 2.0, 1.0, 0.05
    v, w = inputs(u, th0, l)
    assert np.all(v > v_max) and np.all(w > w_max)
    s0 = body_centre(p, th0, l)
    p1, th1 = step(p, th0, u, l, dt, v_max, w_max)
    r = v_max / w_max
    th_end = th0 + w_max * dt
    s_exact = s0 + r * np.stack([np.sin(th_end) - np.sin(th0), np.cos(th0) - np.cos(th_end)], axis=1)
    np.testing.assert_allclose(th1, th_end, rtol=0, atol=1e-14)
    np.testing.assert_allclose(body_centre(p1, th1, l), s_exact, rtol=0, atol=1e-12)
    np.testing.assert_allclose(p1, head(s_exact, th_end, l), rtol=0, atol=1e-12)


def test_limited_arc_is_accurate_for_tiny_turn_rates():
    l = np.array([0.5])
    p = np.array([[300.0, -200.0]])
    th0, v, dt = 1.0, 1.0, 0.05
    worst = 0.0
    for wh in (1.1e-9, 1.5e-9, 2e-9, 3e-9):
        w = wh / (dt / 10)  # ω h with the world's 10 substeps
        c, s = math.cos(th0), math.sin(th0)
        u = np.array([[c * v - l[0] * s * w, s * v + l[0] * c * w]])  # u = M(θ) [v, ω]
        th = np.array([th0])
        s0 = body_centre(p, th, l)
        p1, th1 = step(p, th, u, l, dt, max_speed=10.0)  # a non-binding limit: the substep path
        travelled = float(np.hypot(*(body_centre(p1, th1, l) - s0)[0]))
        worst = max(worst, abs(travelled - v * dt) / (v * dt))
    # The exact arc of length v dt turning by ~1e-8 rad has a chord equal to v dt to ~1e-17 relative.
    assert worst < 1e-10  # rounding of |s| ~ 360 m alone is ~1e-12 relative; the cancelling formula gave 3e-8


def test_a_command_sent_as_v_omega_moves_the_robots_as_the_engine_does_bit_for_bit():
    """An agent sends its u as (v, ω) at its heading (one robot at a time); the world rebuilds u for all at
    once; the engine converts everyone's u both ways at once (`through_inputs`). The same bits either way,
    and within rounding of u itself."""
    rng = np.random.default_rng(3)
    n = 37
    u = rng.normal(size=(n, 2)) * 5
    th = rng.uniform(-4, 4, n)
    l = rng.uniform(0.1, 1.0, n)
    sent = [inputs(u[i:i + 1], th[i:i + 1], l[i:i + 1]) for i in range(n)]  # each agent, alone
    v = np.array([float(a[0][0]) for a in sent])
    w = np.array([float(a[1][0]) for a in sent])
    world = head_velocity(v, w, th, l)
    engine = through_inputs(u, th, l)
    assert np.array_equal(world, engine)
    np.testing.assert_allclose(engine, u, rtol=0, atol=1e-12)
