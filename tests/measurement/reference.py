"""An independent reference for the simulator: scipy's DOP853 with events.

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
