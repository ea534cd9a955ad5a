"""Calibration of a torsion rig: stiffness k and the fixture's own inertia I0.

Each reference is the empty fixture or the fixture with a known added
inertia I_i, and a measured small-amplitude natural frequency ω_n,i (from a
trace, or from the main frequency ω_m and amplitude modulation ζ of the
monocular-vision torsion pendulum paper ("Research on the Measurement Technology of Rotational Inertia of Rigid Body Based on the Principles of Monocular Vision and Torsion Pendulum"): ω_n² = ω_m² + ζ²). The model is

    1/ω_n,i² = (I0 + I_i)/k

a straight line in I_i. It is fitted by (weighted) least squares over all
references — not solved from one pair as that paper's eq. 16 does, which also
mistakes the total for the added load — so that k and I0 come with
uncertainties and a residual that shows a bad reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .errors import CalibrationError


@dataclass(frozen=True)
class Cylinder:
    """A solid reference cylinder standing parallel to the pendulum axis.

    mass: kg; diameter: m; distance: m from the pendulum axis to its own axis;
    own_inertia: kg·m² about its own axis (default m·d²/8).
    """

    mass: float
    diameter: float
    distance: float
    own_inertia: float | None = None

    def __post_init__(self) -> None:
        for name, unit in (("mass", "kg"), ("diameter", "m")):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v > 0 and math.isfinite(v)):
                raise CalibrationError(f"cylinder {name} must be > 0 {unit}, got {v!r}")
        if not (isinstance(self.distance, (int, float)) and self.distance >= 0):
            raise CalibrationError(f"cylinder distance must be >= 0 m, got {self.distance!r}")

    @property
    def inertia(self) -> float:
        """About the pendulum axis (parallel-axis theorem), kg·m²."""
        own = self.own_inertia if self.own_inertia is not None else self.mass * self.diameter**2 / 8.0
        return own + self.mass * self.distance**2


@dataclass(frozen=True)
class Reference:
    """One calibration point.

    added_inertia: known inertia on the fixture, kg·m² (0 for the empty fixture).
    omega_n: small-amplitude natural angular frequency, rad/s, and its 1σ (optional).
    """

    name: str
    added_inertia: float
    omega_n: float
    omega_n_std: float | None = None

    @classmethod
    def from_damped(cls, name: str, added_inertia: float, omega_m: float, zeta: float) -> "Reference":
        """From the main frequency ω_m (rad/s) and amplitude modulation ζ (1/s, either sign)."""
        return cls(name, added_inertia, math.sqrt(omega_m**2 + zeta**2))


@dataclass(frozen=True)
class Calibration:
    """k (N·m/rad) and I0 (kg·m²) with 1σ, and the fit's residual per reference."""

    stiffness: float
    stiffness_std: float | None
    tare_inertia: float
    tare_inertia_std: float | None
    correlation: float | None
    references: tuple[Reference, ...]
    residuals: tuple[float, ...] = field(default=())  # inertia misfit per reference, kg·m²

    def to_dict(self) -> dict:
        return {
            "stiffness": self.stiffness, "stiffness_std": self.stiffness_std,
            "tare_inertia": self.tare_inertia, "tare_inertia_std": self.tare_inertia_std,
            "correlation": self.correlation,
            "references": [
                {"name": r.name, "added_inertia": r.added_inertia, "omega_n": r.omega_n,
                 "omega_n_std": r.omega_n_std, "inertia_residual": res}
                for r, res in zip(self.references, self.residuals)
            ],
        }

    def report(self) -> str:
        def pm(v: float, s: float | None, unit: str) -> str:
            return f"{v:.6g} ± {s:.2g} {unit}" if s is not None else f"{v:.6g} {unit} (no uncertainty: 2 references)"
        lines = ["[[Calibration]] torsion rig",
                 f"    stiffness k     = {pm(self.stiffness, self.stiffness_std, 'N·m/rad')}",
                 f"    tare inertia I0 = {pm(self.tare_inertia, self.tare_inertia_std, 'kg·m²')}",
                 "    reference            added I [kg·m²]   ω_n [rad/s]   misfit [kg·m²]"]
        for r, res in zip(self.references, self.residuals):
            lines.append(f"    {r.name:<20} {r.added_inertia:>14.6g} {r.omega_n:>13.6g} {res:>+15.3g}")
        return "\n".join(lines)


def calibrate_torsion(references: Sequence[Reference]) -> Calibration:
    """Fit k and I0 from references (at least two distinct added inertias)."""
    refs = tuple(references)
    if len(refs) < 2:
        raise CalibrationError(f"calibration needs at least 2 references (empty fixture and a known load); got {len(refs)}")
    I = np.array([r.added_inertia for r in refs], dtype=float)
    w = np.array([r.omega_n for r in refs], dtype=float)
    if not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise CalibrationError("calibration: every reference needs omega_n > 0 rad/s")
    if np.any(I < 0):
        raise CalibrationError("calibration: added inertias must be >= 0 kg·m²")
    if np.ptp(I) == 0:
        raise CalibrationError("calibration: all references have the same added inertia; expected different known loads")
    x = 1.0 / w**2
    stds = [r.omega_n_std for r in refs]
    if all(s is not None and s > 0 for s in stds):
        sx = 2.0 * np.array(stds) / w**3
        weights = 1.0 / sx
    else:
        weights = np.ones_like(x)
    A = np.vstack([np.ones_like(I), I]).T
    Aw = A * weights[:, None]
    coef, *_ = np.linalg.lstsq(Aw, x * weights, rcond=None)
    a, b = coef
    if b <= 0:
        raise CalibrationError("calibration: the period does not grow with the added inertia; check the references")
    k = 1.0 / b
    I0 = a / b
    residual_x = x - A @ coef
    dof = len(refs) - 2
    k_std = I0_std = corr = None
    if dof > 0:
        s2 = float(np.sum((residual_x * weights) ** 2)) / dof
        cov = s2 * np.linalg.inv(Aw.T @ Aw)
        # k = 1/b, I0 = a/b: gradients with respect to (a, b)
        gk = np.array([0.0, -1.0 / b**2])
        gI = np.array([1.0 / b, -a / b**2])
        k_std = float(math.sqrt(gk @ cov @ gk))
        I0_std = float(math.sqrt(gI @ cov @ gI))
        corr = float((gk @ cov @ gI) / (k_std * I0_std)) if k_std > 0 and I0_std > 0 else None
    residual_I = tuple(float(v) for v in residual_x * k)
    return Calibration(k, k_std, I0, I0_std, corr, refs, residual_I)
