"""Unicycle plant with head point and feedback linearization (eqs. 1-3). Pure and batched.

State per robot: head point p (N, 2) and heading θ (N,); the body centre is s = p - l [cos θ, sin θ].
The world receives the commanded head-point velocity u and applies [v, ω] = M(θ)⁻¹ u continuously over
the step with u held (zero-order hold). Without actuator limits the head point then moves by exactly
u·dt and θ has a closed form: with φ = atan2(u_y, u_x) and ψ = θ - φ, ψ̇ = -(‖u‖/l) sin ψ, so
tan(ψ/2) decays as exp(-‖u‖ t / l). With limits (|v| <= v_max, |ω| <= ω_max) the body is integrated in
substeps on exact arcs and the head point no longer follows u: that lag is part of what the world emulates.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import norm2

Array = NDArray[np.float64]
SUBSTEPS = 10


def wrap(a: Array) -> Array:
    """Angles to (-π, π]."""
    return -((-a + np.pi) % (2 * np.pi) - np.pi)


def body_centre(p: Array, theta: Array, l: Array) -> Array:
    """s = p - l [cos θ, sin θ]: (N, 2), (N,), (N,) -> (N, 2)."""
    return p - l[:, None] * np.stack([np.cos(theta), np.sin(theta)], axis=1)


def head_point(s: Array, theta: Array, l: Array) -> Array:
    """Eq. (2): p = s + l [cos θ, sin θ]."""
    return s + l[:, None] * np.stack([np.cos(theta), np.sin(theta)], axis=1)


def inputs(u: Array, theta: Array, l: Array) -> tuple[Array, Array]:
    """[v, ω] = M(θ)⁻¹ u (eq. 3 inverted): (N, 2), (N,), (N,) -> v (N,), ω (N,)."""
    c, s = np.cos(theta), np.sin(theta)
    v = u[:, 0] * c + u[:, 1] * s
    w = (-u[:, 0] * s + u[:, 1] * c) / l
    return v, w


def head_velocity(v: Array, w: Array, theta: Array, l: Array) -> Array:
    """u = M(θ) [v, ω] (eq. 3): the head point's velocity under the body's (v, ω): (N,) x 4 -> (N, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([v * c - l * w * s, v * s + l * w * c], axis=1)


def through_inputs(u: Array, theta: Array, l: Array) -> Array:
    """The command u as it reaches the robot: sent as its (v, ω) (`inputs`), applied as `head_velocity`.
    The agent sends (v, ω) and the world rebuilds u; the in-process engine goes through the same two steps,
    so both move the robots by the same bits. (N, 2) -> (N, 2), equal to u up to rounding."""
    v, w = inputs(u, theta, l)
    return head_velocity(v, w, theta, l)


def step(p: Array, theta: Array, u: Array, l: Array, dt: float, max_speed: float = 0.0,
         max_turn_rate: float = 0.0) -> tuple[Array, Array]:
    """Advance the robots by dt under command u. Returns the new (p (N, 2), θ (N,)).

    max_speed / max_turn_rate of 0 mean no limit.
    """
    if max_speed <= 0.0 and max_turn_rate <= 0.0:
        return p + u * dt, _heading_exact(theta, u, l, dt)
    return _step_limited(p, theta, u, l, dt, max_speed, max_turn_rate)


def _heading_exact(theta: Array, u: Array, l: Array, dt: float) -> Array:
    speed = norm2(u)
    phi = np.arctan2(u[:, 1], u[:, 0])
    psi0 = wrap(theta - phi)
    decay = np.exp(speed * -dt / l)  # (-speed) * dt, the same product
    half = psi0 / 2
    psi = 2.0 * np.arctan2(np.sin(half) * decay, np.cos(half))
    return np.where(speed > 0.0, wrap(phi + psi), theta)


def _step_limited(p: Array, theta: Array, u: Array, l: Array, dt: float, max_speed: float,
                  max_turn_rate: float) -> tuple[Array, Array]:
    s = body_centre(p, theta, l)
    th = theta.copy()
    h = dt / SUBSTEPS
    for _ in range(SUBSTEPS):
        v, w = inputs(u, th, l)
        if max_speed > 0.0:
            v = np.clip(v, -max_speed, max_speed)
        if max_turn_rate > 0.0:
            w = np.clip(w, -max_turn_rate, max_turn_rate)
        # Exact arc for constant (v, ω) over h, written without cancellation:
        # chord = v h sinc(ω h / 2), along the mid-step heading θ + ω h / 2.
        half = w * h / 2
        chord = v * h * np.sinc(half / np.pi)  # np.sinc(x) = sin(πx) / (πx)
        mid = th + half
        s = s + np.stack([chord * np.cos(mid), chord * np.sin(mid)], axis=1)
        th = th + w * h
    th = wrap(th)
    return head_point(s, th, l), th


def step_vw(p: Array, theta: Array, v: Array, w: Array, l: Array, dt: float, max_speed: float = 0.0,
            max_turn_rate: float = 0.0) -> tuple[Array, Array, Array, Array]:
    """ROS 2 mode: the body's (v, ω) held over the step, as a robot base holds its last cmd_vel, saturated
    to the limits (0: none). The body moves on the exact arc. Returns the new (p, θ) and the applied (v, ω)."""
    if max_speed > 0.0:
        v = np.clip(v, -max_speed, max_speed)
    if max_turn_rate > 0.0:
        w = np.clip(w, -max_turn_rate, max_turn_rate)
    half = w * dt / 2
    chord = v * dt * np.sinc(half / np.pi)
    mid = theta + half
    s = body_centre(p, theta, l) + np.stack([chord * np.cos(mid), chord * np.sin(mid)], axis=1)
    th = wrap(theta + w * dt)
    return head_point(s, th, l), th, v, w


def arc_twist(v_mps: float, omega_radps: float, l_m: float, dt: float) -> tuple[float, float]:
    """The twist whose exact arc over dt (a robot base holding it: `step_vw`) moves the head point as far as the
    continuous (v, ω) = M(θ)⁻¹ u (`inputs`) moves it at once over dt: by exactly u dt. Scalars (one command).

    Held as a twist, the continuous (v, ω) turns the robot by ω dt = |u⊥| dt / l in a step and moves the head
    point elsewhere once that is not small: past |u| = 2 l / dt (20 m/s at l = 0.5 m, dt = 0.05 s; the
    repulsion's |u| reaches 65 m/s) heading toward u is unstable and the robot spins in place instead of going
    where the law sent it.

    In the robot's frame u dt is D = (X, Y) = (v dt, l ω dt) (M(θ) = R(θ) diag(1, l)): no heading needed. A body
    turning by a = ω' dt on an arc moves its head point by ρ (sin a, 1 - cos a) + l (cos a - 1, sin a),
    ρ = v' / ω'; eliminating ρ leaves sin(a/2) ((X + 2l) sin(a/2) - Y cos(a/2)) = 0, so a = 2 atan(Y / (X + 2l))
    (the root with |a| <= π; Y = 0: a straight line), and v' dt is the body centre's chord, D - l (cos a - 1,
    sin a), over sinc(a/2). For |u| dt << l it tends to (v, ω)."""
    x, y = v_mps * dt, l_m * omega_radps * dt
    half = math.atan2(y, x + 2.0 * l_m)  # a / 2, then the root within [-π/2, π/2]
    if half > math.pi / 2:
        half -= math.pi
    elif half < -math.pi / 2:
        half += math.pi
    a = 2.0 * half
    chord = (x + l_m * (1.0 - math.cos(a))) * math.cos(half) + (y - l_m * math.sin(a)) * math.sin(half)
    return chord / (dt * _sinc(half)), a / dt


def arc_head_speed(v_mps: float, omega_radps: float, l_m: float, dt: float) -> float:
    """How fast the head point goes over a step of dt under a twist held: the length of its displacement (which
    the heading does not change) over dt. `step_vw`'s arc (no limits) for one twist, in scalars: the world bounds
    each cmd_vel by it (reconswarm/net/trust/admission.py): 0.3 µs, where `step_vw` on arrays of one takes 20 µs."""
    half = omega_radps * dt / 2.0
    chord = v_mps * dt * _sinc(half)
    a = 2.0 * half
    dx, dy = chord * math.cos(half) + l_m * (math.cos(a) - 1.0), chord * math.sin(half) + l_m * math.sin(a)
    return math.hypot(dx, dy) / dt


def _sinc(x: float) -> float:
    """sin(x) / x (1 at 0)."""
    return math.sin(x) / x if x != 0.0 else 1.0
