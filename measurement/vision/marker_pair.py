"""Swing angle from two markers on the pendulum, with the camera's oblique view measured from them.

Two markers fixed to a rigid pendulum keep their distance. Seen square-on, the
vector v from marker a to marker b sweeps a circle as the pendulum swings. A
camera whose image plane is not parallel to the swing plane (weak perspective:
an affine map of the plane) sees an ellipse instead, and the angle read from
the image is off by stretch·sin 2θ + shear·cos 2θ (θ from the image's +y axis):
the law of the identification's `view` effect, which can only guess it from the
swing's dynamics and then absorbs whatever physics the model lacks.

Here the ellipse is measured from the marker positions alone: its quadratic
form Q (vᵀ·Q·v = 1 for every sample, linear least squares) and the symmetric
square root S = Q^½ map it back onto a circle, and the angle of S·v is the
swing angle seen square-on. No dynamics enter, so the correction cannot take
the place of a missing effect.

Angles are those of v, from the image's +y axis (down) towards +x (right), in
rad, unwrapped. Pixel positions are in px. Pure numpy; parsing only, no file I/O.
"""

from __future__ import annotations

import csv
from dataclasses import asdict, dataclass
from typing import Iterable

import numpy as np

from ..errors import VisionError
from ..flags import CAMERA_PERSPECTIVE
from ..trace import Trace, csv_content, csv_header

#: the marker track CSV's columns: time (s) and the two markers' image positions (px)
MARKER_COLUMNS = ("t", "ax", "ay", "bx", "by")
#: a sample whose distance from the fitted ellipse exceeds this many robust σ is a
#: tracking glitch (a wrong blob): it does not enter the view
OUTLIER_SIGMAS = 6.0
#: fewest samples the view is measured from
MIN_SAMPLES = 20
#: least turn of the marker pair (rad) over which the ellipse of its vector, the camera's oblique view, is measured
MIN_VIEW_SWING = 0.2
#: largest 1σ of the measured axis ratio for the view correction to be applied (``view_trace``)
MAX_VIEW_STD = 0.02
#: the swing's angle range is cut into this many bins to see how the marker distance follows the angle
ANGLE_BINS = 12
#: a systematic distance change (relative) beyond which the report says the view is more than oblique
DISTANCE_PATTERN_NOTED = 0.005


@dataclass(frozen=True)
class MarkerTrack:
    """Two markers tracked in the image: t (s), a and b (n×2, px; x right, y down).

    missing: rows of the file without both markers (dropped, counted here).
    """

    t: np.ndarray
    a: np.ndarray
    b: np.ndarray
    source: str = "markers"
    missing: int = 0


@dataclass(frozen=True)
class PairView:
    """The camera's view of the swing plane, measured from a rigid marker pair.

    axis_ratio: minor over major axis of the ellipse the pair's vector sweeps (1: square-on), 1σ.
    major_axis: direction of the major axis, rad from the image's +y axis towards +x, in (−π/2, π/2].
    stretch, shear: the view's distortion in image axes (dimensionless, 1σ each); uncorrected,
        the angle reads off by stretch·sin 2θ + shear·cos 2θ.
    separation: median distance of the markers, px. radius_scatter: RMS of the corrected
        distance about its mean, relative (tracking noise and what an affine view leaves).
    distance_pattern: the largest systematic change of the corrected distance with the angle,
        relative (the mean over each of ANGLE_BINS bins of the swing): what an oblique view does
        not explain, a perspective (parts of the swing nearer the camera) or a marker tracked
        with a bias that depends on its position. Noise averages out of it.
    samples: samples the view was measured from; rejected: samples off the ellipse by more
        than OUTLIER_SIGMAS robust σ (tracking glitches; still in the trace, not in the view).
    matrix: S = Q^½ scaled to determinant 1, row-major (2×2): the correction, v ↦ S·v.
    """

    axis_ratio: float
    axis_ratio_std: float
    major_axis: float
    stretch: float
    stretch_std: float
    shear: float
    shear_std: float
    separation: float
    radius_scatter: float
    distance_pattern: float
    samples: int
    rejected: int
    matrix: tuple[float, float, float, float]

    def angle(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Swing angle seen square-on (rad, unwrapped) from marker positions a, b (n×2, px)."""
        s = np.asarray(self.matrix, dtype=float).reshape(2, 2)
        return _direction((np.asarray(b, float) - np.asarray(a, float)) @ s.T)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["matrix"] = list(self.matrix)
        return d

    def report(self) -> str:
        """Three lines a measurement engineer reads."""
        return (f"camera view measured from the marker pair ({self.samples} samples, {self.rejected} off the ellipse "
                f"rejected): axis ratio {self.axis_ratio:.4f} ± {self.axis_ratio_std:.4f}, major axis at "
                f"{np.degrees(self.major_axis):+.1f}° from the image's vertical\n"
                f"uncorrected the angle would read off by stretch·sin 2θ + shear·cos 2θ with stretch "
                f"{self.stretch:+.4f} ± {self.stretch_std:.4f}, shear {self.shear:+.4f} ± {self.shear_std:.4f}; "
                f"marker distance {self.separation:.1f} px, scatter {100 * self.radius_scatter:.2f} %\n"
                f"after that view the marker distance still changes with the angle by up to "
                f"{100 * self.distance_pattern:.1f} %: "
                + ("the camera sees the swing plane obliquely and nothing else shows"
                   if self.distance_pattern < DISTANCE_PATTERN_NOTED else
                   "more than an oblique view explains (perspective: parts of the swing nearer the camera, or a "
                   "marker tracked with a bias); the angle keeps an error of that kind"))


def pair_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of the vector a→b as the image shows it (rad, unwrapped), no view correction."""
    return _direction(np.asarray(b, float) - np.asarray(a, float))


def _direction(v: np.ndarray) -> np.ndarray:
    return np.unwrap(np.arctan2(v[:, 0], v[:, 1]))


def _view_terms(q: np.ndarray) -> tuple[np.ndarray, float, float, float, float, np.ndarray]:
    """From Q's entries (q11, q12, q22): S normalised, axis ratio, major axis, stretch, shear, Q's eigenvalues."""
    Q = np.array([[q[0], q[1]], [q[1], q[2]]])
    w, V = np.linalg.eigh(Q)
    if w[0] <= 0:
        raise VisionError("the marker pair's vector does not trace an ellipse (its quadratic form is not positive "
                          "definite); expected two markers fixed to the swinging pendulum")
    s = V @ np.diag(np.sqrt(w)) @ V.T
    s = s / np.sqrt(np.linalg.det(s))
    ratio = float(np.sqrt(w[0] / w[1]))
    major = V[:, 0]  # the smallest eigenvalue of Q is the longest axis of the ellipse
    major_axis = float(np.arctan2(major[0], major[1]))
    if major_axis <= -np.pi / 2:
        major_axis += np.pi
    elif major_axis > np.pi / 2:
        major_axis -= np.pi
    # S ∝ I − E with E = [[stretch, shear], [shear, −stretch]] (first order)
    stretch = float((s[1, 1] - s[0, 0]) / 2)
    shear = float(-s[0, 1])
    return s, ratio, major_axis, stretch, shear, w


def measure_view(a: np.ndarray, b: np.ndarray) -> PairView:
    """Measure the camera's view from marker positions a, b (n×2, px) over a swing.

    The fit is linear in Q; samples off the ellipse by more than OUTLIER_SIGMAS robust σ are
    dropped from it (twice re-fitted). The 1σ values allow for the samples' correlation in time
    (lag-1 autocorrelation of the residual), as a tracker's errors are not independent.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 2:
        raise VisionError(f"marker positions must be two n×2 arrays (x, y in px); got {a.shape} and {b.shape}")
    v = b - a
    dist = np.hypot(v[:, 0], v[:, 1])
    if v.shape[0] < MIN_SAMPLES:
        raise VisionError(f"{v.shape[0]} samples of the marker pair; expected at least {MIN_SAMPLES} over a swing")
    if not np.all(np.isfinite(v)) or np.any(dist == 0):
        raise VisionError("marker positions must be finite and the two markers distinct; expected px coordinates")
    span = np.ptp(_direction(v))
    if span < MIN_VIEW_SWING:
        raise VisionError(f"the marker pair turns by only {span:.3f} rad; expected a swing of at least "
                          f"{MIN_VIEW_SWING} rad to measure the camera's view")
    X = np.column_stack([v[:, 0] ** 2, 2 * v[:, 0] * v[:, 1], v[:, 1] ** 2])
    keep = np.ones(len(v), dtype=bool)
    q = np.zeros(3)
    for _ in range(3):
        q = np.linalg.lstsq(X[keep], np.ones(int(keep.sum())), rcond=None)[0]
        quad = X @ q
        radius = np.sqrt(np.clip(quad, 0.0, None)) - 1.0
        sigma = 1.4826 * float(np.median(np.abs(radius[keep] - np.median(radius[keep]))))
        keep_new = np.abs(radius) <= OUTLIER_SIGMAS * max(sigma, 1e-12)
        if int(keep_new.sum()) < MIN_SAMPLES or np.array_equal(keep_new, keep):
            break
        keep = keep_new
    s, ratio, major_axis, stretch, shear, _ = _view_terms(q)
    r = (X @ q - 1.0)[keep]
    Xk = X[keep]
    dof = max(len(r) - 3, 1)
    rho = float(np.dot(r[1:], r[:-1]) / np.dot(r, r)) if np.dot(r, r) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.95)
    cov = np.linalg.inv(Xk.T @ Xk) * (float(np.dot(r, r)) / dof) * (1 + rho) / (1 - rho)

    def terms(qq: np.ndarray) -> np.ndarray:
        _, rr, _, st, sh, _ = _view_terms(qq)
        return np.array([rr, st, sh])

    base = np.array([ratio, stretch, shear])
    jac = np.empty((3, 3))
    for j in range(3):
        h = 1e-6 * max(abs(q[j]), 1e-12 + np.max(np.abs(q)))
        dq = np.zeros(3)
        dq[j] = h
        jac[:, j] = (terms(q + dq) - base) / h
    std = np.sqrt(np.clip(np.diag(jac @ cov @ jac.T), 0.0, None))
    corrected = np.hypot(*(v[keep] @ s.T).T)
    relative = corrected / np.mean(corrected) - 1.0
    angle = _direction(v[keep] @ s.T)
    edges = np.quantile(angle, np.linspace(0.0, 1.0, ANGLE_BINS + 1))
    which = np.clip(np.searchsorted(edges, angle, side="right") - 1, 0, ANGLE_BINS - 1)
    pattern = max(abs(float(np.mean(relative[which == k]))) for k in range(ANGLE_BINS) if np.any(which == k))
    return PairView(
        axis_ratio=ratio, axis_ratio_std=float(std[0]), major_axis=major_axis,
        stretch=stretch, stretch_std=float(std[1]), shear=shear, shear_std=float(std[2]),
        separation=float(np.median(dist)), radius_scatter=float(np.std(corrected) / np.mean(corrected)),
        distance_pattern=pattern,
        samples=int(keep.sum()), rejected=int((~keep).sum()),
        matrix=(float(s[0, 0]), float(s[0, 1]), float(s[1, 0]), float(s[1, 1])),  # row-major
    )


def parse_marker_csv(lines: Iterable[str], source: str = "markers") -> MarkerTrack:
    """Parse a marker track CSV: a header row with columns t (s), ax, ay, bx, by (px).

    Other columns are ignored and lines starting with '#' are comments. A row where a
    marker was not found (an empty cell) is dropped and counted in ``missing``.
    """
    content = csv_content(lines)
    if not content:
        raise VisionError(f"{source}: no header row; expected a CSV with columns {', '.join(MARKER_COLUMNS)}")
    header = csv_header(content)
    absent = [c for c in MARKER_COLUMNS if c not in header]
    if absent:
        raise VisionError(f"{source}: missing column(s) {', '.join(absent)} in header {header}; expected t (s) and "
                          "the two markers' image positions ax, ay, bx, by (px)")
    idx = [header.index(c) for c in MARKER_COLUMNS]
    rows: list[list[float]] = []
    missing = 0
    for n, line in content[1:]:
        cells = next(csv.reader([line]))
        values = [cells[i].strip() if i < len(cells) else "" for i in idx]
        if values[0] == "":
            raise VisionError(f"{source}: line {n} has no time; expected t (s) in every row")
        if any(v == "" for v in values[1:]):
            missing += 1
            continue
        try:
            row = [float(v) for v in values]
        except ValueError:
            raise VisionError(f"{source}: line {n}: non-numeric cell in {values!r}; expected t in s and positions "
                              "in px") from None
        if not all(np.isfinite(row)):
            raise VisionError(f"{source}: line {n}: NaN/inf in {values!r}; expected finite numbers (leave a lost "
                              "marker's cells empty)")
        rows.append(row)
    if not rows:
        raise VisionError(f"{source}: no row with both markers ({missing} without); expected rows of "
                          f"{', '.join(MARKER_COLUMNS)}")
    arr = np.asarray(rows)
    return MarkerTrack(t=arr[:, 0], a=arr[:, 1:3], b=arr[:, 3:5], source=source, missing=missing)


def view_trace(track: MarkerTrack) -> Trace:
    """The swing of a marker track, the camera's view measured and removed when the swing shows it (it turns
    by ``MIN_VIEW_SWING`` or more and the axis ratio comes out within ``MAX_VIEW_STD``), else the angle as the
    image shows it (``meta["view_note"]`` says so): a small swing's scale matters only through sin θ, which
    is then close to θ."""
    span = float(np.ptp(_direction(np.asarray(track.b, float) - np.asarray(track.a, float))))
    if span < MIN_VIEW_SWING:
        note = (f"the swing spans {span:.3f} rad, less than the {MIN_VIEW_SWING} rad that show the camera's oblique "
                "view: the angle is taken as the image shows it")
    else:
        view = measure_view(track.a, track.b)
        if view.axis_ratio_std <= MAX_VIEW_STD:
            return pair_trace(track, view)
        # a correction less certain than the error it would remove: the angle as seen (its scale matters
        # only through sin θ, and the identification fits the angle's scale where the rig allows it)
        note = (f"the swing does not determine the camera's view (axis ratio {view.axis_ratio:.3f} ± "
                f"{view.axis_ratio_std:.3f}): the angle is taken as the image shows it")
    trace = pair_trace(track, None)
    trace.meta["view_note"] = note
    return trace


def pair_trace(track: MarkerTrack, view: PairView | None) -> Trace:
    """The swing as a Trace: the angle of a→b, corrected for ``view`` (None: as the image shows it)."""
    angle = pair_angle(track.a, track.b) if view is None else view.angle(track.a, track.b)
    meta = {"sensor": "camera, marker pair", "rows_without_both_markers": track.missing}
    flags: tuple[str, ...] = ()
    if view is not None:
        meta["view"] = view.to_dict()
        if view.distance_pattern >= DISTANCE_PATTERN_NOTED:
            flags = (CAMERA_PERSPECTIVE,)
    return Trace(track.t, angle, source=track.source, flags=flags, meta=meta)
