"""Independent references: for the simulator, scipy's DOP853 with events; for a release, a plain damped sinusoid.

Written separately from measurement.integrator (different method, different
code) so that tests do not check the fit against data made by the very
simulator the fit uses. Torque laws are written out here, not taken from
the effect classes.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp


class _Turn:
    """solve_ivp event: the velocity crossing zero in ``direction``; it ends the integration (a turning point)."""

    terminal = True

    def __init__(self, direction: float):
        self.direction = direction

    def __call__(self, _t: float, z: np.ndarray) -> float:
        return z[1]


def reference_motion(kind: str, omega_n: float, t: np.ndarray, theta0: float, *, viscous: float = 0.0,
                     coulomb: float = 0.0, quadratic: float = 0.0, cubic: float = 0.0,
                     extra=None) -> np.ndarray:
    """θ(t) for θ'' = −ω_n² r(θ) − c θ' − b s [cos θ] − K s θ'² − k3 θ³ (all per unit J).

    Released at rest from theta0 at t[0]. Half-swing by half-swing with the
    direction s fixed; at each turning point the pendulum sticks when the
    static friction can hold it.
    """
    w2 = omega_n**2

    def restoring(x):
        return w2 * (math.sin(x) if kind == "compound" else x) + cubic * x**3

    def friction(x):
        return coulomb * (abs(math.cos(x)) if kind == "compound" else 1.0)

    out = np.full(t.size, np.nan)
    t0, x0, v0 = float(t[0]), float(theta0), 0.0
    s = -math.copysign(1.0, restoring(x0))
    if abs(restoring(x0)) <= friction(x0):
        return np.full(t.size, theta0)
    t_end = float(t[-1])
    while t0 < t_end:
        def rhs(_, z, s=s):
            x, v = z
            return [v, -restoring(x) - viscous * v - s * friction(x) - quadratic * s * v * v]

        sol = solve_ivp(rhs, (t0, t_end), [x0, v0], method="DOP853", rtol=1e-12, atol=1e-14,
                        events=_Turn(direction=-s), dense_output=True, first_step=1e-6)
        seg = (t >= t0) & (t <= sol.t[-1])
        out[seg] = sol.sol(t[seg])[0]
        if sol.status != 1:
            break
        t0 = float(sol.t_events[0][0])
        x0, v0 = float(sol.y_events[0][0][0]), 0.0
        if abs(restoring(x0)) <= friction(x0):
            out[t > t0] = x0
            break
        s = -s
    if extra is not None:
        out = out + extra(t)
    return out


def sensor(rng: np.random.Generator, angle: np.ndarray, noise: float, bits: int | None = 17) -> np.ndarray:
    y = angle + rng.normal(0.0, noise, angle.size)
    if bits:
        step = 2 * math.pi / (1 << bits)
        y = np.round(y / step) * step
    return y


def reading_columns(path) -> tuple[np.ndarray, np.ndarray]:
    """t (s) and the reading of a release's file: its angle (rad), or a gyro's rate (rad/s) read as it is, for a
    plain fit that reads any sensor (a marker track: its angle with the camera's view measured)."""
    from service.sources.dispatch import load_source

    trace = load_source(path)
    return trace.t, trace.angle


def damped_sinusoid(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(ω_n, its σ) in rad/s of y = c + e^(−σt)(A cos ω_d t + B sin ω_d t) fitted to every sample, ω_n = √(ω_d² + σ²).

    The plainest fit that would do, by variable projection, its σ under white noise (what such a fit
    would state): the yardstick of the spread between releases of one object. NaN where y has no swing.
    """
    from scipy.optimize import least_squares

    from measurement.signal import find_swings

    t = t - t[0]
    ok = np.isfinite(y)
    t, y = t[ok], y[ok]
    wd0 = find_swings(t, y).damped_frequency
    if not math.isfinite(wd0):
        return math.nan, math.nan

    def basis(p: np.ndarray) -> np.ndarray:
        e = np.exp(-p[0] * t)
        return np.column_stack([np.ones_like(t), e * np.cos(p[1] * t), e * np.sin(p[1] * t)])

    def residual(p: np.ndarray) -> np.ndarray:
        b = basis(p)
        coef, *_ = np.linalg.lstsq(b, y, rcond=None)
        return b @ coef - y

    sol = least_squares(residual, [0.05, wd0], x_scale=[0.05, 0.01 * wd0], method="lm")
    sigma, wd = sol.x
    coef, *_ = np.linalg.lstsq(basis(sol.x), y, rcond=None)
    c, a, b = coef

    def full(q: np.ndarray) -> np.ndarray:  # every parameter, for the covariance
        e = np.exp(-q[0] * t)
        return q[2] + e * (q[3] * np.cos(q[1] * t) + q[4] * np.sin(q[1] * t)) - y

    q = np.array([sigma, wd, c, a, b])
    jac = np.empty((t.size, q.size))
    for i in range(q.size):
        h = 1e-7 * max(abs(q[i]), 1e-3)
        dq = np.zeros_like(q)
        dq[i] = h
        jac[:, i] = (full(q + dq) - full(q - dq)) / (2 * h)
    r = full(q)
    s2 = float(r @ r) / max(t.size - q.size, 1)
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    wn = math.hypot(wd, sigma)
    grad = np.array([sigma / wn, wd / wn])
    return wn, float(math.sqrt(max(grad @ cov[:2, :2] @ grad, 0.0)))
