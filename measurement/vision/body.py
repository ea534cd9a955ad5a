"""From the points a locator followed to the swing angle: the pivot, the oblique view, the angle.

Every target but the edge gives per frame a vector fixed to the swinging body
(tag: across it; two blobs: one to the other; patch: its rotated axis; one
blob: from the pivot to it). The swing turns that vector in the image plane,
so its direction is the angle (seen face-on or along the axis alike). A
camera looking obliquely at the swing plane sees the vector's circle as an
ellipse: the two-marker route's view correction (``marker_pair``) measures
and removes it when the swing is wide enough to show the ellipse; a smaller
swing is taken as seen (its scale matters only through sin θ, which is then
close to θ).

One blob needs the pivot: given in the camera file, or the centre of the
arc the blob traces (a circle fitted to its positions; the fit's radius
scatter and the arc it spans say whether it can be trusted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import VisionError
from ..trace import Trace
from .marker_pair import MarkerTrack, view_trace

#: least arc (rad) of a blob's path for its centre to be found (below it the pivot must be given)
MIN_ARC = 0.1
#: largest scatter of the blob's distance from the fitted centre, relative to the radius
MAX_ARC_SCATTER = 0.02


@dataclass(frozen=True)
class Pivot:
    """The centre of the swing in the image: u, v (px); radius: the blob's distance from it (px);
    fitted: found from the arc (else given); scatter: RMS of the distance about the radius, px."""

    u: float
    v: float
    radius: float
    fitted: bool
    scatter: float = 0.0
    u_std: float = 0.0
    v_std: float = 0.0
    radius_std: float = 0.0

    def to_dict(self) -> dict:
        out = {"pivot_u_px": round(self.u, 2), "pivot_v_px": round(self.v, 2), "pivot_radius_px": round(self.radius, 2),
               "pivot_fitted": self.fitted}
        if self.fitted:
            # 1σ from the arc's scatter: a short arc leaves the pivot loose, which scales the angle (through
            # sin θ only a little: the scale error ε moves ω_n by about ε·θ²/8 on a gravity pendulum)
            out.update({"pivot_scatter_px": round(self.scatter, 3), "pivot_u_std_px": round(self.u_std, 2),
                        "pivot_v_std_px": round(self.v_std, 2), "pivot_radius_std_px": round(self.radius_std, 2)})
        return out


def fit_pivot(b: np.ndarray, source: str = "video") -> Pivot:
    """The centre of the arc traced by the points b (n×2, px): algebraic circle fit refined by Gauss–Newton
    on the geometric distances. Raises VisionError when the arc is too short or not a circle."""
    u, v = b[:, 0], b[:, 1]
    A = np.column_stack([u, v, np.ones_like(u)])
    c = np.linalg.lstsq(A, u * u + v * v, rcond=None)[0]
    cu, cv = c[0] / 2, c[1] / 2
    for _ in range(20):
        du, dv = u - cu, v - cv
        r = np.hypot(du, dv)
        J = np.column_stack([-du / r, -dv / r, -np.ones_like(r)])
        R = float(np.mean(r))
        step = np.linalg.lstsq(J, -(r - R), rcond=None)[0]
        cu, cv = cu + step[0], cv + step[1]
        if abs(step[0]) + abs(step[1]) < 1e-6:
            break
    r = np.hypot(u - cu, v - cv)
    R = float(np.mean(r))
    scatter = float(np.std(r))
    J = np.column_stack([-(u - cu) / r, -(v - cv) / r, -np.ones_like(r)])
    try:
        cov = np.linalg.inv(J.T @ J) * scatter**2
        stds = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        stds = np.full(3, math.inf)
    arc = float(np.ptp(np.unwrap(np.arctan2(u - cu, v - cv))))
    if not math.isfinite(R) or arc < MIN_ARC or scatter > MAX_ARC_SCATTER * R:
        raise VisionError(f"{source}: the blob's path is not an arc whose centre can be found (it spans "
                          f"{arc:.3f} rad, scatter {scatter:.1f} px about a radius of {R:.0f} px); expected a "
                          f"swing of at least {MIN_ARC} rad, or give the pivot in the camera file ([target] pivot = [u, v])")
    return Pivot(float(cu), float(cv), R, True, scatter, float(stds[0]), float(stds[1]), float(stds[2]))


def provisional_angle(obs, pivot: tuple[float, float] | None) -> float:
    """The angle (rad) of one frame's observation before the whole swing is known (live display): the body
    vector's direction, from ``pivot`` (px) for a single blob; NaN when the target was not found."""
    if not obs.found or obs.b is None:
        return math.nan
    a = obs.a if obs.a is not None else pivot
    if a is None:
        return math.nan
    return math.atan2(obs.b[0] - a[0], obs.b[1] - a[1])


def body_trace(t: np.ndarray, a: np.ndarray | None, b: np.ndarray, *, pivot: tuple[float, float] | None,
               source: str = "video", missing: int = 0) -> tuple[Trace, dict]:
    """The angle trace (rad) of a body vector a→b over times t (s); a None: a single blob, whose pivot is
    ``pivot`` or the centre of its arc. Returns the trace and what was measured on the way (pivot, view)."""
    meta: dict = {}
    if a is None:
        if pivot is not None:
            p = Pivot(pivot[0], pivot[1], float(np.median(np.hypot(b[:, 0] - pivot[0], b[:, 1] - pivot[1]))), False)
        else:
            p = fit_pivot(b, source)
        meta.update(p.to_dict())
        a = np.tile([p.u, p.v], (len(b), 1))
    trace = view_trace(MarkerTrack(t=t, a=a, b=b, source=source, missing=missing))
    trace.meta.pop("sensor", None)
    return trace, meta
