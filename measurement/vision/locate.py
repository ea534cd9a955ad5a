"""From a grey frame to the marker edge's sub-pixel position.

The marker is a vertical boundary between a dark and a bright field: the
highest-contrast long vertical edge in view. Per frame:

1. Region of interest: a window around where the edge is expected (the last
   position plus the last motion), over the marker's rows. Without a lock
   (first frame, after a loss) the whole frame is searched: horizontal
   gradient averaged over a tall window of rows, strongest response.
2. Noise filtering: the ROI is smoothed along the edge (a box over
   ``smooth_rows`` rows), which averages the sensor noise without moving a
   vertical edge.
3. Sub-pixel edge per row: the peak of the central-difference gradient with
   the expected polarity, refined by a parabola through the peak and its two
   neighbours (pixel locking stays below 0.015 px for a blur σ of 0.5–1.5 px).
4. Lens: the edge points are undistorted with the calibrated coefficients
   (points, not the image: exact and cheap, and no resampling blur).
5. A line x = a + b·(y − y_ref) is fitted to the points in ideal normalised
   coordinates, with outlier rows rejected; x at the reference row y_ref
   (fixed at the first lock) is the measurement.

Frames where the edge is too weak, too short, or not straight are rejected
with a reason (never an exception): the caller leaves a gap and flags it.
Hough lines are not used to measure: they quantise the position.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..flags import CORRUPT_FRAME, MARKER_LOST
from .config import CameraModel

# reasons a frame yields no position (strings go into counts and flags)
CORRUPT = CORRUPT_FRAME
LOST = MARKER_LOST


@dataclass(frozen=True)
class TrackerSettings:
    """Knobs of the marker tracker.

    track: follow the marker with a region of interest (False: search the whole frame every time).
    roi_half_width: least half-width of the search window around the predicted edge, px.
    search_rows: rows averaged when searching the whole frame for the edge.
    smooth_rows: rows of the box filter along the edge (noise filtering); odd.
    min_rows: fewest rows with an edge for a valid line.
    min_contrast: weakest edge accepted: peak of the central difference I(u+1) − I(u−1), grey levels
        (the step height for a sharp edge; blur lowers it).
    relock_ratio: after a loss, an edge must have at least this share of the first lock's contrast
        (so the cylinder's silhouette is not taken for the marker).
    max_residual: largest RMS distance of the rows from the fitted line, px.
    trim_rows: rows left out at each end of the marker (its corners are not a clean edge).
    reject_repeated: rows identical to the previous frame are a decoder's stand-in for a damaged
        frame, not a measurement. True only for an intra-only stream (MJPEG, a V4L2 camera): an
        inter-frame codec (H.264, HEVC) repeats an unchanged region by design; switch off too for
        noise-free synthetic frames of a still marker.
    roi: (x0, y0, x1, y1) px, x1/y1 exclusive: where the edge is searched (None: the whole frame).
    """

    track: bool = True
    roi_half_width: int = 16
    search_rows: int = 41
    smooth_rows: int = 5
    min_rows: int = 15
    min_contrast: float = 20.0
    relock_ratio: float = 0.5
    max_residual: float = 0.35
    trim_rows: int = 4
    reject_repeated: bool = True
    roi: tuple[int, int, int, int] | None = None


@dataclass(frozen=True)
class MarkerObservation:
    """What one frame says about the marker.

    found: the edge was measured; else ``reason`` says why not (``marker_lost`` or ``corrupt_frame``)
    and ``detail`` explains.
    x: ideal normalised lateral coordinate of the edge at the reference row (dimensionless; NaN if not found).
    y_ref: that reference row, ideal normalised y (fixed at the tracker's first lock).
    u, v: raw pixel position of that point, px.
    slope: dx/dy of the edge line (normalised units; the image tilt of the marker).
    rows: rows used; residual: RMS of the rows about the line, px; contrast: edge strength, grey
    levels (median over the rows of the peak central difference I(u+1) − I(u−1)).
    roi: (row0, row1, col0, col1) searched, px. points: (u, v) of every row used, px (only when asked).
    """

    found: bool
    reason: str = ""
    detail: str = ""
    x: float = math.nan
    y_ref: float = math.nan
    u: float = math.nan
    v: float = math.nan
    slope: float = math.nan
    rows: int = 0
    residual: float = math.nan
    contrast: float = math.nan
    roi: tuple[int, int, int, int] | None = None
    points: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    @property
    def tilt_deg(self) -> float:
        """Angle of the marker edge from the image's vertical, degrees.

        Positive when the edge's top leans towards −u: what a camera rolled by that angle about its
        optical axis (``CameraPose.roll``) sees of a vertical edge.
        """
        return math.degrees(math.atan(self.slope)) if math.isfinite(self.slope) else math.nan


def check_frame(frame: object, camera: CameraModel) -> str:
    """'' if ``frame`` is a usable grey image of the camera's size, else why not."""
    if frame is None:
        return "no image (the decoder returned nothing)"
    if not isinstance(frame, np.ndarray):
        return f"not an image array ({type(frame).__name__})"
    if frame.ndim != 2:
        return f"expected a grey (2-D) image, got shape {frame.shape}"
    if frame.shape != (camera.height, camera.width):
        return f"image is {frame.shape[1]}×{frame.shape[0]} px, the camera file says {camera.width}×{camera.height}"
    if frame.dtype != np.uint8:
        return f"expected 8-bit pixels, got {frame.dtype}"
    return ""


def to_grey(frame: np.ndarray) -> np.ndarray:
    """A decoded frame (grey, BGR or BGRA, 8 bit) as a 2-D uint8 grey image."""
    if frame.ndim == 3 and frame.shape[2] == 3:
        return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    if frame.ndim == 3 and frame.shape[2] == 4:
        return cv2.cvtColor(frame, cv2.COLOR_BGRA2GRAY)
    if frame.ndim == 3 and frame.shape[2] == 1:
        return frame[:, :, 0]
    return frame


class MarkerTracker:
    """Finds the marker edge frame after frame, following it with a region of interest.

    Stateful (the lock: rows of the marker, reference row, polarity, last
    positions); ``reset()`` forgets it. Not thread-safe: one per stream.
    """

    def __init__(self, camera: CameraModel, settings: TrackerSettings = TrackerSettings()):
        self.camera = camera
        self.settings = settings
        self.reset()

    def reset(self) -> None:
        """Forget the lock: the next frame is searched whole and sets a new reference row."""
        self._rows: tuple[int, int] | None = None  # marker rows (inclusive start, exclusive stop)
        self._polarity = 0  # +1: dark → bright with growing u
        self._y_ref: float | None = None  # reference row, ideal normalised y
        self._lock_contrast = 0.0
        self._last_u: float | None = None
        self._velocity = 0.0  # px/frame
        self._locked = False
        self._previous: tuple[int, np.ndarray] | None = None  # first row and rows of the last frame

    @property
    def y_ref(self) -> float | None:
        """Reference row of the measurement, ideal normalised y (None before the first lock)."""
        return self._y_ref

    # -- search -----------------------------------------------------------
    def _search(self, img: np.ndarray) -> tuple[tuple[int, int], int, int, float] | str:
        """Whole-frame search: (rows, column, polarity, contrast) of the strongest long vertical edge, or why not."""
        s = self.settings
        f = img.astype(np.float32)
        g = np.zeros_like(f)
        g[:, 1:-1] = f[:, 2:] - f[:, :-2]
        k = min(s.search_rows, img.shape[0] - (1 - img.shape[0] % 2))
        tall = cv2.blur(g, (1, k), borderType=cv2.BORDER_CONSTANT) if k > 1 else g
        if s.roi is not None:
            # only an edge inside the region of interest may be the marker
            x0, y0, x1, y1 = s.roi
            inside = np.zeros_like(tall)
            inside[y0:y1, x0:x1] = tall[y0:y1, x0:x1]
            tall = inside
        i, j = (int(n) for n in np.unravel_index(int(np.argmax(np.abs(tall))), tall.shape))
        peak = float(tall[i, j])
        polarity = 1 if peak > 0 else -1
        # the vertical run of rows along which this edge continues (it may lean or bend slightly)
        half = 3
        strong = 0.5 * abs(peak)
        rows = []
        col = j
        top, bottom = (s.roi[1], s.roi[3]) if s.roi is not None else (0, img.shape[0])
        for direction in (-1, 1):
            r, c = i, col
            while top <= r < bottom:
                lo, hi = max(c - half, 1), min(c + half + 1, img.shape[1] - 1)
                seg = polarity * g[r, lo:hi]
                if seg.size == 0 or seg.max() < strong:
                    break
                c = lo + int(np.argmax(seg))
                rows.append(r)
                r += direction
        if not rows:
            return "no vertical edge in the frame"
        r0, r1 = min(rows), max(rows) + 1
        contrast = float(np.median((polarity * g[r0:r1, max(j - half, 1):min(j + half + 1, img.shape[1] - 1)]).max(axis=1)))
        return (r0, r1), j, polarity, contrast

    # -- measure ----------------------------------------------------------
    def _measure(self, img: np.ndarray, rows: tuple[int, int], c0: int, c1: int, polarity: int,
                 keep_points: bool) -> MarkerObservation:
        s = self.settings
        H, W = img.shape
        r0, r1 = rows
        c0, c1 = max(c0, 0), min(c1, W)
        roi_box = (r0, r1, c0, c1)
        if r1 - r0 < s.min_rows or c1 - c0 < 5:
            return MarkerObservation(False, LOST, "the marker window left the image", roi=roi_box)
        raw = img[r0:r1, c0:c1]
        stale = self._stale_rows(raw, r0, c0)
        roi: np.ndarray = raw.astype(np.float32)
        if s.smooth_rows > 1:
            roi = cv2.blur(roi, (1, s.smooth_rows), borderType=cv2.BORDER_REPLICATE)
        g = polarity * (roi[:, 2:] - roi[:, :-2])  # gradient at columns c0+1 … c1−2
        k = np.argmax(g, axis=1)
        idx = np.arange(g.shape[0])
        peak = g[idx, k]
        inner = (k > 0) & (k < g.shape[1] - 1)
        kc = np.clip(k, 1, g.shape[1] - 2)
        gm, g0, gp = g[idx, kc - 1], g[idx, kc], g[idx, kc + 1]
        den = gm - 2.0 * g0 + gp
        with np.errstate(divide="ignore", invalid="ignore"):
            delta = np.where(den < 0, 0.5 * (gm - gp) / den, 0.0)
        contrast = float(np.median(peak)) if peak.size else 0.0
        # a row counts when its edge is as strong as the marker's (not noise, not a corner)
        ok = inner & (peak >= max(0.6 * contrast, s.min_contrast)) & (np.abs(delta) <= 0.5)
        if stale.any():
            ok &= ~stale
            if ok.sum() < s.min_rows:
                return MarkerObservation(False, CORRUPT, f"the marker's rows repeat the previous frame bit for bit "
                                         f"({int(stale.sum())} rows: a frame the decoder could not decode)", roi=roi_box)
        if contrast < s.min_contrast or ok.sum() < s.min_rows:
            return MarkerObservation(False, LOST, f"edge too weak or too short ({int(ok.sum())} rows, "
                                     f"strength {contrast:.0f} grey levels)", roi=roi_box, contrast=contrast)
        u = c0 + 1 + k[ok] + delta[ok]
        v = (r0 + idx[ok]).astype(float)
        x, y = self.camera.undistort(u, v)
        y_ref = self._y_ref if self._y_ref is not None else float(np.median(y))
        keep = np.ones(x.size, dtype=bool)
        a = b = 0.0
        resid_px = math.inf
        for _ in range(3):
            yy = y[keep] - y_ref
            A = np.stack([np.ones_like(yy), yy], axis=1)
            (a, b), *_ = np.linalg.lstsq(A, x[keep], rcond=None)
            r = (x - a - b * (y - y_ref)) * self.camera.fx  # px
            resid_px = float(np.sqrt(np.mean(r[keep] ** 2)))
            new_keep = np.abs(r) <= max(3.0 * resid_px, 0.05)
            if keep.sum() >= s.min_rows and (new_keep == keep).all():
                break
            keep = new_keep
            if keep.sum() < s.min_rows:
                break
        if keep.sum() < s.min_rows or resid_px > s.max_residual:
            return MarkerObservation(False, LOST, f"edge is not a straight line ({int(keep.sum())} rows, "
                                     f"{resid_px:.2f} px RMS)", roi=roi_box, contrast=contrast)
        # raw pixel of the measured point, for display and for the next window
        u_ref, v_ref = self.camera.distort(np.array([a]), np.array([y_ref]))
        pts = (u[keep], v[keep]) if keep_points else None
        return MarkerObservation(True, x=float(a), y_ref=float(y_ref), u=float(u_ref[0]), v=float(v_ref[0]), slope=float(b),
                                 rows=int(keep.sum()), residual=resid_px, contrast=contrast, roi=roi_box,
                                 points=pts)

    def _stale_rows(self, raw: np.ndarray, r0: int, c0: int) -> np.ndarray:
        """Rows of the window that equal the previous frame's pixel for pixel.

        Sensor noise never repeats a row of the marker's edge exactly; a decoder that cannot
        decode (part of) a frame does: FFmpeg conceals a damaged MJPEG frame with the previous
        frame's pixels. Measured, those rows would put the old angle at the new time.
        """
        stale = np.zeros(raw.shape[0], dtype=bool)
        if not self.settings.reject_repeated or self._previous is None:
            return stale
        p0, band = self._previous
        lo, hi = max(r0, p0), min(r0 + raw.shape[0], p0 + band.shape[0])
        if hi > lo:
            stale[lo - r0:hi - r0] = np.all(raw[lo - r0:hi - r0] == band[lo - p0:hi - p0, c0:c0 + raw.shape[1]], axis=1)
        return stale

    def locate(self, frame: np.ndarray | None, keep_points: bool = False) -> MarkerObservation:
        """Measure the marker in one grey frame (uint8, camera size). Never raises on bad frames."""
        why = check_frame(frame, self.camera)
        if why:
            self._locked = False
            return MarkerObservation(False, CORRUPT, why)
        assert frame is not None, "check_frame passed it: a grey image of the camera's size"
        try:
            return self._locate(frame, keep_points)
        finally:
            if self.settings.reject_repeated:
                # a copy: a caller may decode the next frame into the same buffer
                r0, r1 = self._rows if self._rows is not None else (0, frame.shape[0])
                self._previous = (r0, frame[r0:r1].copy())

    def _locate(self, img: np.ndarray, keep_points: bool) -> MarkerObservation:
        s = self.settings
        if self._locked and s.track:
            assert self._last_u is not None and self._rows is not None, "a lock (_update) has the marker's column and rows"
            pred = self._last_u + self._velocity
            half = s.roi_half_width + int(math.ceil(2 * abs(self._velocity)))
            c = int(round(pred))
            obs = self._measure(img, self._rows, c - half, c + half + 1, self._polarity, keep_points)
            if obs.found:
                self._update(obs)
                return obs
            # fall through: search the whole frame before declaring the marker lost
        found = self._search(img)
        if isinstance(found, str):
            self._locked = False
            return MarkerObservation(False, LOST, found)
        (r0, r1), col, polarity, contrast = found
        if self._lock_contrast and (contrast < s.relock_ratio * self._lock_contrast or polarity != self._polarity):
            self._locked = False
            return MarkerObservation(False, LOST, f"strongest edge (strength {contrast:.0f}) is not the marker "
                                     f"(locked at {self._lock_contrast:.0f})")
        if contrast < s.min_contrast:
            self._locked = False
            return MarkerObservation(False, LOST, f"strongest edge has a strength of only {contrast:.0f} grey levels")
        trim = s.trim_rows
        rows = (r0 + trim, r1 - trim) if self._rows is None else self._rows
        if self._rows is not None and not (rows[0] < r1 and r0 < rows[1]):
            rows = (r0 + trim, r1 - trim)  # the marker is somewhere else now: take its new rows
        obs = self._measure(img, rows, col - s.roi_half_width, col + s.roi_half_width + 1, polarity, keep_points)
        if not obs.found:
            self._locked = False
            return obs
        if self._rows is None:
            # first lock: its rows, polarity, contrast and reference row hold from now on
            self._rows, self._polarity, self._lock_contrast, self._y_ref = rows, polarity, obs.contrast, obs.y_ref
        self._last_u, self._velocity = None, 0.0
        self._update(obs)
        return obs

    def _update(self, obs: MarkerObservation) -> None:
        if self._last_u is not None and self._locked:
            self._velocity = obs.u - self._last_u
        else:
            self._velocity = 0.0
        self._last_u = obs.u
        self._locked = True
