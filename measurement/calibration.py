"""Calibration of a torsion rig: stiffness k and the fixture's own inertia I0.

Each reference is the empty fixture or the fixture with a known added
inertia I_i, and a measured small-amplitude natural frequency ω_n,i (from a
trace, or from the main frequency ω_m and amplitude modulation ζ of the
monocular-vision torsion pendulum paper ("Research on the Measurement Technology of Rotational Inertia of Rigid Body Based on the Principles of Monocular Vision and Torsion Pendulum"): ω_n² = ω_m² + ζ²). The model is

    1/ω_n,i² = (I0 + I_i)/k

a straight line in I_i, x_i = a + b·I_i with x = 1/ω_n², a = I0/k, b = 1/k.
It is fitted over all references — not solved from one pair as that paper's
eq. 16 does, which also mistakes the total for the added load — so that k and
I0 come with uncertainties and a residual that shows a bad reference.

Both coordinates carry errors: the known inertia its certificate's σ(I_i),
the measured x its σ(x_i) = 2·σ(ω_n,i)/ω_n,i³. The fit is a weighted least
squares with the effective variance σ_i² = σ(x_i)² + b²·σ(I_i)² (Deming's
errors-in-variables regression, iterated to a fixed point in b; for a straight
line it is the maximum-likelihood solution of York et al., "Unified equations
for the slope, intercept, and standard errors of the best straight line",
Am. J. Phys. 72 (2004)). The covariance of (a, b) is (AᵀWA)⁻¹ with W = diag(1/σ_i²):
what the stated uncertainties allow. It is scaled up by the Birge ratio²
χ²/ν when the references scatter beyond their σ (χ² above its 95 % quantile
for ν = n − 2: they are then understated), never down: with 3 references and 2 unknowns the misfit has one degree of
freedom, and a lucky small misfit must not promise more than the certificates.
Only when no reference states any uncertainty does the misfit alone set the
σ (and the calibration says so). k = 1/b and I0 = a/b and their covariance
follow by first-order propagation.

A reference released more than once (several references of one name, one known
inertia) is one point of the fit, its releases averaged (``_points``): its
certificate's error is common to its releases, and n independent points would
shrink k's σ by √n. Its releases show the rig's scatter between releases, which
one record cannot see: ``reproducibility`` pools the references' relative
within-name deviations of ω_n as ISO 5725-2 does
(``measurement.reproducibility.pooled``, ν = Σ(n_i − 1)), the figure the rig
file keeps with its calibration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .errors import CalibrationError
from .reproducibility import Reproducibility, calibrated, pooled


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

    added_inertia: known inertia on the fixture, kg·m² (0 for the empty fixture), and its 1σ
    ``added_inertia_std`` (the certificate; None: not stated).
    omega_n: small-amplitude natural angular frequency, rad/s, and its 1σ (optional).
    certificate: the identifier of the certificate the known inertia comes from (optional), kept with the
    calibration as the record of what it rests on.
    """

    name: str
    added_inertia: float
    omega_n: float
    omega_n_std: float | None = None
    added_inertia_std: float | None = None
    certificate: str | None = None

    @classmethod
    def from_damped(cls, name: str, added_inertia: float, omega_m: float, zeta: float,
                    added_inertia_std: float | None = None) -> "Reference":
        """From the main frequency ω_m (rad/s) and amplitude modulation ζ (1/s, either sign)."""
        return cls(name, added_inertia, math.sqrt(omega_m**2 + zeta**2), added_inertia_std=added_inertia_std)


def cylinder_inertia_std(c: Cylinder, mass_std: float = 0.0, diameter_std: float = 0.0,
                         distance_std: float = 0.0) -> float:
    """1σ of a cylinder's inertia about the pendulum axis (kg·m²) from the 1σ of its mass, diameter, distance.

    I = m·d²/8 + m·L²: ∂I/∂m = d²/8 + L², ∂I/∂d = m·d/4, ∂I/∂L = 2·m·L (a stated own_inertia: its mass term is L² only).
    """
    dm = (c.diameter**2 / 8.0 if c.own_inertia is None else 0.0) + c.distance**2
    dd = c.mass * c.diameter / 4.0 if c.own_inertia is None else 0.0
    dl = 2.0 * c.mass * c.distance
    return math.sqrt((dm * mass_std) ** 2 + (dd * diameter_std) ** 2 + (dl * distance_std) ** 2)


@dataclass(frozen=True)
class Calibration:
    """k (N·m/rad) and I0 (kg·m²) with 1σ, their covariance, and the fit's residual per reference.

    basis: what the uncertainties rest on ("stated": the references' σ, scaled by the Birge ratio when
    they scatter beyond it; "misfit": no σ was stated, the misfit alone). birge_ratio: √(χ²/ν) of the
    weighted fit (None without degrees of freedom or without stated σ).
    """

    stiffness: float
    stiffness_std: float | None
    tare_inertia: float
    tare_inertia_std: float | None
    correlation: float | None
    references: tuple[Reference, ...]
    residuals: tuple[float, ...] = field(default=())  # inertia misfit per reference, kg·m²
    covariance: float | None = None  # cov(k, I0), N·m/rad·kg·m²
    basis: str = "stated"
    birge_ratio: float | None = None
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {
            "stiffness": self.stiffness, "stiffness_std": self.stiffness_std,
            "tare_inertia": self.tare_inertia, "tare_inertia_std": self.tare_inertia_std,
            "correlation": self.correlation, "stiffness_tare_covariance": self.covariance,
            "basis": self.basis, "birge_ratio": self.birge_ratio, "notes": list(self.notes),
            "references": [
                {"name": r.name, "added_inertia": r.added_inertia, "added_inertia_std": r.added_inertia_std,
                 **({"certificate": r.certificate} if r.certificate is not None else {}),
                 "omega_n": r.omega_n, "omega_n_std": r.omega_n_std, "inertia_residual": res}
                for r, res in zip(self.references, self.residuals)
            ],
        }

    def report(self) -> str:
        def pm(v: float, s: float | None, unit: str) -> str:
            if s is None:
                return f"{v:.6g} {unit} (no uncertainty: 2 references and none states its σ)"
            return f"{v:.6g} ± {s:.2g} {unit} ({100 * s / abs(v):.2g} %)" if v else f"{v:.6g} ± {s:.2g} {unit}"
        lines = ["[[Calibration]] torsion rig",
                 f"    stiffness k     = {pm(self.stiffness, self.stiffness_std, 'N·m/rad')}",
                 f"    tare inertia I0 = {pm(self.tare_inertia, self.tare_inertia_std, 'kg·m²')}"]
        if self.correlation is not None:
            lines.append(f"    correlation r(k, I0) = {self.correlation:+.4f} (one regression: kept in every J_object)")
        birge = f", Birge ratio {self.birge_ratio:.2f}" if self.birge_ratio is not None else ""
        basis = ("the references' stated uncertainties (weighted, errors in the known inertia and in ω_n)"
                 if self.basis == "stated" else "the misfit alone: no reference states an uncertainty")
        lines.append(f"    uncertainty from {basis}{birge}")
        lines += [f"    note: {n}" for n in self.notes]
        lines.append("    reference            added I [kg·m²]      u(I)    ω_n [rad/s]   misfit [kg·m²]")
        for r, res in zip(self.references, self.residuals):
            u = f"{r.added_inertia_std:.2g}" if r.added_inertia_std is not None else "—"
            lines.append(f"    {r.name:<20} {r.added_inertia:>14.6g} {u:>9} {r.omega_n:>13.6g} {res:>+15.3g}")
        return "\n".join(lines)


#: the references are taken to scatter beyond their stated σ when χ² exceeds this quantile of its distribution
CONSISTENCY_LEVEL = 0.95


def calibrate_torsion(references: Sequence[Reference]) -> Calibration:
    """Fit k and I0 from references (at least two distinct added inertias); see the module doc."""
    refs = _checked(references)
    I, x, sx, sI = _points(refs)
    A = np.vstack([np.ones_like(I), I]).T
    stated = bool(np.any(sx > 0) or np.any(sI > 0))
    notes: list[str] = []
    coef = np.linalg.lstsq(A, x, rcond=None)[0]
    s_eff = np.ones_like(x)
    if stated:
        coef, s_eff = _effective_variance(A, x, sx, sI, coef)
        unstated = [n for n, a, b in zip(dict.fromkeys(r.name for r in refs), sx, sI) if a == 0 and b == 0]
        if unstated:
            notes.append(f"no uncertainty stated for {', '.join(unstated)}: treated as 1/1000 of the smallest "
                         "stated one (state added_inertia_std and omega_n_std)")
    a, b = coef
    if b <= 0:
        raise CalibrationError("calibration: the period does not grow with the added inertia; check the references")
    residual_x = x - A @ coef
    # each release's own misfit, from the line its reference's mean fixed
    x_each = 1.0 / np.array([r.omega_n for r in refs], dtype=float) ** 2
    residual_each = x_each - (a + b * np.array([r.added_inertia for r in refs], dtype=float))
    cov, birge = _covariance(A, s_eff, residual_x, stated, notes)
    k_std = I0_std = corr = kI_cov = None
    if cov is not None:
        # k = 1/b, I0 = a/b: gradients with respect to (a, b)
        gk = np.array([0.0, -1.0 / b**2])
        gI = np.array([1.0 / b, -a / b**2])
        k_std = float(math.sqrt(gk @ cov @ gk))
        I0_std = float(math.sqrt(gI @ cov @ gI))
        kI_cov = float(gk @ cov @ gI)
        corr = kI_cov / (k_std * I0_std) if k_std > 0 and I0_std > 0 else None
    k = 1.0 / b
    residual_I = tuple(float(v) for v in residual_each * k)
    return Calibration(k, k_std, a / b, I0_std, corr, refs, residual_I, kI_cov, "stated" if stated else "misfit",
                       birge, tuple(notes))


def reproducibility(references: Sequence[Reference]) -> Reproducibility | None:
    """The scatter of ω_n between the releases of each reference released more than once (by name), pooled
    (source "rig"); None when none is. A name given with two different known inertias is refused: those are two
    references, not one released again."""
    groups = _by_name(references)
    for name, rs in groups.items():
        if any(not math.isclose(r.added_inertia, rs[0].added_inertia, rel_tol=1e-9, abs_tol=1e-15) for r in rs):
            raise CalibrationError(f"reference {name!r} is given with different known inertias "
                                   f"({', '.join(f'{r.added_inertia:.6g}' for r in rs)} kg·m²); expected one name "
                                   "per reference (a reference released again repeats its table unchanged)")
    figure = pooled([r.omega_n for r in rs] for rs in groups.values())
    if figure.relative is None:
        return None
    return calibrated(figure.relative, figure.dof, figure.groups, figure.releases)


def _by_name(references: Sequence[Reference]) -> dict[str, list[Reference]]:
    """The references grouped by name, in their order: one reference's releases together."""
    groups: dict[str, list[Reference]] = {}
    for r in references:
        groups.setdefault(r.name, []).append(r)
    return groups


def _points(refs: Sequence[Reference]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The fit's points (I, x = 1/ω², σ(x), σ(I)): one per reference, its releases averaged. A reference released
    n times has one certificate: its error is common to its releases, so it is one point, not n independent ones
    (that would shrink k's σ by √n). Its x is the releases' mean, σ(x)² the larger of their own mean σ² and the
    calibration's pooled scatter between releases (``reproducibility``), over n."""
    repro = reproducibility(refs)
    rel = 0.0 if repro is None or repro.relative is None else repro.relative
    rows = []
    for rs in _by_name(refs).values():
        xs = np.array([1.0 / r.omega_n**2 for r in rs])
        own = np.array([2.0 * (r.omega_n_std or 0.0) / r.omega_n**3 for r in rs])
        var = max(float(np.mean(own**2)), (2.0 * rel * float(xs.mean())) ** 2) if len(rs) > 1 else float(own[0] ** 2)
        rows.append((rs[0].added_inertia, float(xs.mean()), math.sqrt(var / len(rs)), rs[0].added_inertia_std or 0.0))
    I, x, sx, sI = (np.array(c, dtype=float) for c in zip(*rows))
    return I, x, sx, sI


def _checked(references: Sequence[Reference]) -> tuple[Reference, ...]:
    """The references, refused unless at least two distinct added inertias ≥ 0, ω_n > 0 and σ ≥ 0."""
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
    for r in refs:
        for name, v in (("omega_n_std", r.omega_n_std), ("added_inertia_std", r.added_inertia_std)):
            if v is not None and not (math.isfinite(v) and v >= 0):
                raise CalibrationError(f"reference {r.name!r}: {name} must be a standard uncertainty >= 0, got {v!r}")
    return refs


def _effective_variance(A: np.ndarray, x: np.ndarray, sx: np.ndarray, sI: np.ndarray,
                        coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the line's coefficients, each reference's effective σ of x): the slope enters the weights, a fixed
    point in a few steps."""
    s_eff = np.ones_like(x)
    for _ in range(50):
        s_eff = np.sqrt(sx**2 + (coef[1] * sI) ** 2)
        zero = s_eff <= 0
        if np.any(zero):
            # a reference with no stated σ would be an exact constraint; it gets a tiny one, and it is said
            s_eff[zero] = 1e-3 * float(np.min(s_eff[~zero]))
        new = np.linalg.lstsq(A / s_eff[:, None], x / s_eff, rcond=None)[0]
        done = abs(new[1] - coef[1]) <= 1e-12 * abs(coef[1])
        coef = new
        if done:
            break
    return coef, s_eff


def _covariance(A: np.ndarray, s_eff: np.ndarray, residual_x: np.ndarray, stated: bool,
                notes: list[str]) -> tuple[np.ndarray | None, float | None]:
    """(the coefficients' covariance, the Birge ratio): from the stated σ, scaled up when the references scatter
    beyond them; from the misfit alone when none is stated (None: no degree of freedom for it). Says so in
    ``notes``."""
    dof = len(residual_x) - 2
    if not stated:
        if dof <= 0:
            return None, None
        notes.append(f"no reference states an uncertainty: σ from the misfit alone ({dof} degree(s) of freedom), "
                     "which may be far too small by chance; state added_inertia_std (the certificate)")
        return float(np.sum(residual_x**2)) / dof * np.linalg.inv(A.T @ A), None
    Aw = A / s_eff[:, None]
    cov = np.linalg.inv(Aw.T @ Aw)
    if dof <= 0:
        return cov, None
    chi2 = float(np.sum((residual_x / s_eff) ** 2))
    birge = math.sqrt(chi2 / dof)
    from scipy.special import chdtri  # only here: the calibration module loads without scipy

    if chi2 > chdtri(dof, 1.0 - CONSISTENCY_LEVEL):
        # the references scatter beyond their stated σ: those are understated, by this much
        notes.append(f"the references scatter {birge:.2g} × beyond their stated uncertainties: "
                     "k and I0's σ scaled up by that (Birge ratio)")
        return cov * birge**2, birge
    return cov, birge
