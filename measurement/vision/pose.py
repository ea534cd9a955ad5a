"""Camera pose error: the yaw of the optical axis, estimated from the swing itself.

Why the data tell the yaw. The pendulum's equation of motion is odd: it is
unchanged under θ → −θ (viscous, Coulomb and quadratic damping, cubic
stiffness, gravity's sin θ all are), so a free swing has half-wave symmetry
and no even harmonics. The projection of a camera looking straight at the
swing axis is odd too. A yawed camera's is not: the angle computed with the
wrong yaw ψ' is θ + (ψ' − ψ)·∂θ/∂ψ, and ∂θ/∂ψ grows with θ² (it is
(L/R)·cos α / sqrt(1 − ((L/R)·sin α)²) − 1), so the half-swings on the two
sides differ and a second harmonic appears whose size is proportional to
the yaw error and to the amplitude squared (the monocular-vision torsion pendulum
paper cited in geometry.py sees the same asymmetry in its two envelopes, §4.3).

The fit (yaw as a parameter of the projection, not two envelope points):
the measured image coordinate x(t) is turned into an angle with the exact
projection at yaw ψ; that angle is fitted by a symmetric swing — odd
harmonics 1, 3, 5 of a smooth phase Φ(t) with smoothly varying (B-spline)
amplitudes, on top of a slowly varying zero level — plus the yaw column
∂θ/∂ψ. Gauss–Newton on ψ (the other coefficients are linear) converges in a
few iterations. Only even-order structure can move ψ, and nothing in the
pendulum produces it, so damping of any kind, cubic stiffness and slow zero
drift do not bias the estimate.

The design matrix is sparse (each cubic B-spline lives on four knot intervals), and so is the least-squares
problem it poses: memory and time grow with the samples, never with samples × knots, whatever the length of
the record (a camera left running for half an hour gives thousands of knots).

The marker's rest angle φ0 (the swing's centre seen from the camera) is
estimated on the way: with D (camera to marker at rest) it fixes the
camera–axis distance L (D² = L² + R² − 2·L·R·cos φ0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.interpolate import BSpline
from scipy.sparse.linalg import splu

from .config import MarkerGeometry
from .geometry import angle_from_normalised, axis_distance, d_angle_d_yaw


@dataclass(frozen=True)
class PoseEstimate:
    """The camera's yaw as seen in one swing.

    estimated: False when the record cannot tell (too few swings); ``reason`` says why.
    yaw, yaw_std: ψ and its 1σ (white-residual) uncertainty, rad.
    rest_angle: φ0, rad, the swing's centre seen from the camera; axis_distance: L, m.
    swings: half-swings used; residual_rms: rad, of the symmetric-swing fit; iterations: Gauss–Newton steps.
    """

    estimated: bool
    yaw: float = 0.0
    yaw_std: float = math.nan
    rest_angle: float = 0.0
    axis_distance: float = math.nan
    swings: int = 0
    residual_rms: float = math.nan
    iterations: int = 0
    reason: str = ""

    @property
    def yaw_deg(self) -> float:
        return math.degrees(self.yaw)

    @property
    def yaw_std_deg(self) -> float:
        return math.degrees(self.yaw_std)

    def to_dict(self) -> dict:
        def num(v: float, digits: int) -> float | None:
            # rounded well below the uncertainty: the report is read by people
            return round(float(v), digits) if math.isfinite(v) else None
        return {"yaw_estimated": self.estimated, "yaw_deg": num(self.yaw_deg, 4), "yaw_std_deg": num(self.yaw_std_deg, 4),
                "rest_angle_deg": num(math.degrees(self.rest_angle), 4), "axis_distance_m": num(self.axis_distance, 6),
                "pose_half_swings": self.swings,
                "pose_fit_rms_rad": float(f"{self.residual_rms:.3g}") if math.isfinite(self.residual_rms) else None,
                **({"pose_note": self.reason} if self.reason else {})}


def _crossings(t: np.ndarray, y: np.ndarray, level: float, hysteresis: float) -> np.ndarray:
    """Times (s) at which y crosses ``level``, alternating in direction, linearly interpolated."""
    state = 0
    out = []
    for i in range(1, y.size):
        if state <= 0 and y[i] > level + hysteresis:
            new = 1
        elif state >= 0 and y[i] < level - hysteresis:
            new = -1
        else:
            continue
        if state != 0:
            # last sample on the other side of the level before i
            j = i
            while j > 0 and (y[j - 1] - level) * new > 0:
                j -= 1
            if j > 0:
                y0, y1 = y[j - 1] - level, y[j] - level
                out.append(t[j - 1] + (t[j] - t[j - 1]) * (y0 / (y0 - y1) if y0 != y1 else 0.5))
        state = new
    return np.asarray(out)


def _bspline_basis(t: np.ndarray, t0: float, t1: float, spacing: float) -> sparse.csr_array:
    """Cubic B-spline design matrix on [t0, t1] with knots about ``spacing`` s apart (sparse: four per row)."""
    n_int = max(int(math.ceil((t1 - t0) / spacing)), 1)
    inner = np.linspace(t0, t1, n_int + 1)
    knots = np.concatenate([[t0] * 3, inner, [t1] * 3])
    tt = np.clip(t, t0, t1)
    return sparse.csr_array(BSpline.design_matrix(tt, knots, 3))


class _LeastSquares:
    """Least squares on the columns of a sparse design matrix M: coefficients and residuals.

    The normal equations MᵀM (banded: columns of nearby knots alone overlap) factorised once, then one step
    of iterative refinement on the residual computed from M itself (the corrected semi-normal equations of
    Björck, "Stability analysis of the method of seminormal equations for linear least squares problems"):
    the accuracy of an orthogonal factorisation without its dense Q. Should a column no sample reaches (a
    gap in the track) make them singular, it is pinned at zero by a ridge far below any column's weight.
    """

    def __init__(self, M: sparse.csr_array):
        self.M = M
        self.Mt = sparse.csr_array(M.T)
        gram = sparse.csc_array(self.Mt @ M)
        try:
            self._lu = splu(gram, permc_spec="MMD_AT_PLUS_A")
        except RuntimeError:  # SuperLU: "Factor is exactly singular"
            ridge = 1e-13 * max(float(gram.diagonal().max()), 1e-300)
            try:
                self._lu = splu(sparse.csc_array(gram + ridge * sparse.eye_array(gram.shape[0], format="csc")),
                                permc_spec="MMD_AT_PLUS_A")
            except RuntimeError as exc:
                raise np.linalg.LinAlgError(str(exc)) from exc

    def coefficients(self, y: np.ndarray) -> np.ndarray:
        c = self._lu.solve(self.Mt @ y)
        return c + self._lu.solve(self.Mt @ (y - self.M @ c))

    def residual(self, y: np.ndarray) -> np.ndarray:
        return y - self.M @ self.coefficients(y)


def estimate_yaw(t: np.ndarray, x: np.ndarray, marker: MarkerGeometry, *, harmonics: tuple[int, ...] = (1, 3, 5),
                 max_iterations: int = 12, outlier_sigma: float = 6.0) -> PoseEstimate:
    """Estimate the camera yaw ψ (rad) from a free swing seen at ideal normalised coordinates x(t).

    t: s, increasing (gaps allowed); x: dimensionless, finite. Needs at least
    three full swings; otherwise (or when the swing cannot tell it: a track
    that hardly moves) returns ``estimated=False`` with a reason.
    """
    try:
        return _estimate_yaw(t, x, marker, harmonics, max_iterations, outlier_sigma)
    except np.linalg.LinAlgError:
        return PoseEstimate(False, reason="the swing does not determine the camera yaw (a singular fit: does the "
                            "marker move?)")


def _estimate_yaw(t: np.ndarray, x: np.ndarray, marker: MarkerGeometry, harmonics: tuple[int, ...],
                  max_iterations: int, outlier_sigma: float) -> PoseEstimate:
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.size < 40:
        return PoseEstimate(False, reason=f"only {t.size} samples: too few to estimate the camera yaw")
    theta = angle_from_normalised(x, marker, 0.0, 0.0)
    if not np.isfinite(theta).all():
        return PoseEstimate(False, reason="the marker leaves the cylinder's visible side: geometry does not fit")
    cross = _half_swings(t, theta)
    if cross.size < 7:
        return PoseEstimate(False, reason=f"only {max(cross.size - 1, 0)} half-swings: at least 6 are needed to "
                            "estimate the camera yaw")
    use, M, dc_basis = _symmetric_swing(t, cross, harmonics)
    # Variable projection: the symmetric-swing coefficients are linear, so they are projected out
    # (factorised once per set of samples) and only the yaw is iterated.
    yf = _YawFit(x[use], marker, M)
    for outer in range(3):  # the rest angle changes L a little: refine it
        failed = yf.steps(max_iterations, outlier_sigma if outer == 0 else None)
        if failed:
            return PoseEstimate(False, reason=failed)
        # the zero level of the symmetric fit is the marker's surface angle at rest (relative to the current one)
        th = angle_from_normalised(yf.xu, marker, yf.yaw, yf.rest)[yf.keep]
        coef = yf.fit.coefficients(th)
        shift = float(np.median(dc_basis[yf.keep] @ coef[:dc_basis.shape[1]]))
        yf.rest += shift
        if abs(shift) < 1e-7:
            break
    dof = max(int(yf.keep.sum()) - M.shape[1] - 1, 1)
    rms = float(np.sqrt(np.sum(yf.residual ** 2) / dof))
    return PoseEstimate(True, yaw=yf.yaw, yaw_std=rms / math.sqrt(yf.curvature), rest_angle=yf.rest,
                        axis_distance=axis_distance(marker, yf.rest), swings=int(cross.size - 1), residual_rms=rms,
                        iterations=yf.iterations)


def _half_swings(t: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The times the swing crosses its centre line (the phase's anchors)."""
    span = float(np.percentile(theta, 99) - np.percentile(theta, 1))
    level = float(np.median(theta))
    cross = _crossings(t, theta, level, 0.05 * span)
    if cross.size >= 4:
        # centre of the swing from the record between the first and last crossing (not the hold, not the rest)
        sel = (t >= cross[0]) & (t <= cross[-1])
        level = 0.5 * (float(theta[sel].max()) + float(theta[sel].min()))
        cross = _crossings(t, theta, level, 0.05 * span)
    return cross


def _symmetric_swing(t: np.ndarray, cross: np.ndarray,
                     harmonics: tuple[int, ...]) -> tuple[np.ndarray, sparse.csr_array, sparse.csr_array]:
    """(the samples used, the design matrix of a symmetric swing over them, its slow zero level's columns): the
    harmonics of the phase through the crossings, with amplitudes and the zero level as B-splines in time."""
    period = 2.0 * float(np.median(np.diff(cross)))
    k = np.arange(cross.size) * math.pi
    tn = (cross - cross[0]) / max(cross[-1] - cross[0], 1e-9)
    phase_poly = np.polyfit(tn, k, min(3, cross.size - 2))
    t0, t1 = cross[0] - 0.25 * period, cross[-1] + 0.25 * period
    use = (t >= t0) & (t <= t1)
    tu = t[use]
    phi_t = np.polyval(phase_poly, (tu - cross[0]) / max(cross[-1] - cross[0], 1e-9))
    amp_basis = _bspline_basis(tu, t0, t1, 2.0 * period)
    dc_basis = _bspline_basis(tu, t0, t1, 3.0 * period)
    cols = [dc_basis]
    for h in harmonics:
        cols.append(amp_basis.multiply(np.cos(h * phi_t)[:, None]))
        cols.append(amp_basis.multiply(np.sin(h * phi_t)[:, None]))
    return use, sparse.csr_array(sparse.hstack(cols, format="csr")), dc_basis


class _YawFit:
    """The yaw's Gauss–Newton steps with the symmetric swing projected out: the yaw and rest angle so far, the
    samples kept (glitches dropped once), the last residual and the curvature of the yaw's misfit."""

    def __init__(self, xu: np.ndarray, marker: MarkerGeometry, M: sparse.csr_array):
        self.xu, self.marker, self.M = xu, marker, M
        self.yaw = self.rest = 0.0
        self.keep = np.ones(xu.size, dtype=bool)
        self.fit = _LeastSquares(M)
        self.residual = np.zeros(xu.size)
        self.curvature = math.nan
        self.iterations = 0

    def steps(self, max_iterations: int, outlier_sigma: float | None) -> str | None:
        """Step the yaw until it settles; outlier_sigma: drop the glitches beyond it on the first residual
        (None: not this time). Returns why the fit failed, or None."""
        for it in range(max_iterations):
            self.iterations += 1
            th = angle_from_normalised(self.xu, self.marker, self.yaw, self.rest)[self.keep]
            jac = d_angle_d_yaw(self.xu, self.marker, self.yaw, self.rest)[self.keep]
            if not (np.isfinite(th).all() and np.isfinite(jac).all()):
                return "the yaw fit left the cylinder's visible side (diverged)"
            th_r = self.fit.residual(th)
            jac_r = self.fit.residual(jac)
            self.curvature = float(jac_r @ jac_r)
            if not self.curvature > 0:
                return "the swing shows no sign of the camera yaw (amplitude too small)"
            step = -float(jac_r @ th_r) / self.curvature
            self.yaw += step
            self.residual = th_r + step * jac_r
            if abs(self.yaw) > 0.5:
                return "the yaw fit ran away (> 30°): not a yawed camera, or not a swing"
            if it == 0 and outlier_sigma is not None and self._drop_glitches(outlier_sigma):
                continue
            if abs(step) < 1e-10:
                break
        return None

    def _drop_glitches(self, outlier_sigma: float) -> bool:
        # glitches (a mistracked frame) would pull the fit: dropped once, on the first residual
        r = self.residual
        sigma = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        if not sigma > 0:
            return False
        good = np.abs(r - np.median(r)) <= outlier_sigma * sigma
        if good.all():
            return False
        self.keep[np.flatnonzero(self.keep)[~good]] = False
        self.fit = _LeastSquares(self.M[self.keep])
        return True
