"""What restores the swing: each rig kind's law, r(θ), in one place.

The equation of motion, normalised by the inertia J about the axis, is

    θ'' = −ω_n²·r(θ) − Σ effects            (torsion: r = θ; compound: r = sin θ)

A wire suspension (bifilar: two wires D apart, each R = D/2 from the axis; trifilar: three wires on a
circle of radius R) hangs the part on wires of length L that stay taut and vertical at rest. Twisted by θ,
each wire's lower end moves a chord 2R·sin(θ/2) from under its upper end, so the part rises: its depth
below the upper ends is z(θ) = L·s(θ), s = sqrt(1 − 2e(1 − cos θ)), e = (R/L)². With the part's mass m
and inertia J, inextensible weightless wires and no sway, the Lagrangian ½J·θ'² + ½m·z'(θ)²·θ'² + m·g·z(θ)
gives

    (1 + ω_n²·b·S(θ))·θ'' = −ω_n²·(r(θ) + b·Q(θ)·θ'²) − Σ effects,   ω_n² = m·g·R²/(J·L),  b = R²/(g·L)

    r = sin θ / s     (the wires' torque m·g·R²·sin θ/(L·s) over m·g·R²/L; small swing: k = m·g·R²/L,
                       m·g·D²/(4L) for a bifilar)
    S = sin²θ / s²    (the rising part's kinetic energy, as an inertia m·z'² over J)
    Q = sin θ·cos θ / s² + e·sin³θ / s⁴   (z'·z'' over R²·L·e: the centripetal term of the rise)

m/J is not a further unknown: it is ω_n²·L/(g·R²), so the law carries the rig's geometry (e, b) and ω_n
alone, and its amplitude dependence is the geometry's, never a fitted cubic spring. Nothing here is
small-angle: the one approximation is the ideal suspension (taut, weightless, inextensible wires, the part
turning about the vertical axis through their centre without swaying).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

#: the wire suspensions: their law is the same, with R = D/2 (bifilar) or the wires' circle (trifilar)
WIRE_SUSPENSIONS = ("bifilar", "trifilar")
RIG_KINDS = ("torsion", "compound") + WIRE_SUSPENSIONS


def wire_geometry(radius: float, wire_length: float, g: float) -> tuple[float, float]:
    """(e, b) of a wire suspension: e = (R/L)² (1), b = R²/(g·L) (s²); R, L in m, g in m/s²."""
    return (radius / wire_length) ** 2, radius**2 / (g * wire_length)


def kernel_law(kind: str) -> tuple[str, str, str]:
    """The integrator's law for ``kind`` as (r, S, Q) expressions in x (θ) and the geometry (ge, gb);
    S and Q are "0.0" where the rig's part does not rise."""
    if kind == "compound":
        return "sin(x)", "0.0", "0.0"
    if kind in WIRE_SUSPENSIONS:
        s2 = "(1.0 - 2.0 * ge * (1.0 - cos(x)))"
        return (f"(sin(x) / sqrt({s2}))", f"(gb * sin(x) * sin(x) / {s2})",
                f"(gb * (sin(x) * cos(x) / {s2} + ge * sin(x) ** 3 / ({s2} * {s2})))")
    return "x", "0.0", "0.0"


def _terms(kind: str, theta: np.ndarray, geometry: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r, S, Q (S and Q with b in them) on arrays."""
    theta = np.asarray(theta, dtype=float)
    zero = np.zeros_like(theta)
    if kind == "compound":
        return np.sin(theta), zero, zero
    if kind not in WIRE_SUSPENSIONS:
        return theta, zero, zero
    e, b = geometry
    s2 = 1.0 - 2.0 * e * (1.0 - np.cos(theta))
    sn, cs = np.sin(theta), np.cos(theta)
    return sn / np.sqrt(s2), b * sn * sn / s2, b * (sn * cs / s2 + e * sn**3 / s2**2)


def restoring(kind: str, theta: np.ndarray, geometry: Sequence[float] = ()) -> np.ndarray:
    """r(θ): the restoring torque over the small-swing constant C (J = C/ω_n²), rad."""
    return _terms(kind, theta, geometry)[0]


def restoring_column(kind: str, theta: np.ndarray, rate: np.ndarray, accel: np.ndarray,
                     geometry: Sequence[float] = ()) -> np.ndarray:
    """What multiplies −ω_n² in θ'' = −ω_n²·(…) − Σ effects, from the measured θ, θ', θ'': the equation is linear
    in ω_n² with the rise's inertia and centripetal terms moved to this side."""
    r, s, q = _terms(kind, theta, geometry)
    return r + s * np.asarray(accel, dtype=float) + q * np.asarray(rate, dtype=float) ** 2


def amplitude_factor(kind: str, amplitude: float, omega_n: float = 0.0, geometry: Sequence[float] = ()) -> float:
    """The undamped period at ``amplitude`` (rad) over the small-swing period 2π/ω_n by the rig's own law."""
    if amplitude <= 0 or kind == "torsion":
        return 1.0
    if kind == "compound":
        from scipy.special import ellipk

        return float(2.0 * ellipk(math.sin(min(amplitude, 3.1) / 2.0) ** 2) / math.pi)
    e, b = geometry
    w2 = omega_n**2

    def potential(th: np.ndarray) -> np.ndarray:  # ∫r dθ = (1 − s)/e
        return (1.0 - np.sqrt(1.0 - 2.0 * e * (1.0 - np.cos(th)))) / e

    # θ = A·sin φ takes the turning point's 1/sqrt out of the energy integral
    phi, weights = np.polynomial.legendre.leggauss(64)
    phi = 0.25 * math.pi * (phi + 1.0)
    th = amplitude * np.sin(phi)
    inertia = 1.0 + w2 * _terms(kind, th, geometry)[1]
    drop = np.maximum(potential(np.array([amplitude]))[0] - potential(th), 1e-300)
    quarter = float(np.sum(0.25 * math.pi * weights * amplitude * np.cos(phi) * np.sqrt(inertia / (2.0 * drop))))
    return quarter * 4.0 / (2.0 * math.pi)
