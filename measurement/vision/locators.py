"""From a frame to a vector fixed to the swinging body: tag, blob, two blobs, textured patch.

Each locator follows its target from frame to frame: a window around the
last position is searched first (fast), the whole region of interest when
the target is lost. A frame without the target is an observation with a
reason, never an exception. The observation's points are raw pixel
positions (u right, v down, px): ``a`` and ``b`` span a vector fixed to the
body (for a single blob, ``a`` is None: the pivot is added afterwards), so
the swing angle is that vector's direction (``measurement.vision.body``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..flags import CORRUPT_FRAME, MARKER_LOST
from .target import TargetSpec, dictionary_name

LOST = MARKER_LOST
CORRUPT = CORRUPT_FRAME
#: reason of a frame that only repeats the previous picture (not a flag: no measurement is missing)
REPEATED = "repeated_frame"
#: a frame whose target window differs from the previous frame's by less than this mean absolute
#: difference, grey levels, is the same picture again: a phone's frame-rate conversion duplicates frames
#: and the codec re-encodes the copy with a faint residual (≤ 0.03 seen), where any motion of the target
#: or the sensor's noise changes the window by a grey level or more
DUPLICATE_GREY = 0.25

#: smallest blob accepted, px² (below it, a speck of noise or compression)
MIN_BLOB_AREA = 12
#: enhanced correlation alignment: least correlation of the patch with the frame for a valid pose
MIN_PATCH_CORRELATION = 0.7
#: most pixels of the patch aligned: a larger region of interest is aligned on the frame shrunk by a whole
#: factor (ECC's cost grows with the area: aligned whole, a 240 px square patch ran at 283 frames/s on one core,
#: a 140 px one at 672; shrunk by 2, the 240 px one runs at 1062)
MAX_PATCH_PIXELS = 160 * 160
#: search window around the last position, in target sizes (plus twice the last motion)
WINDOW_SIZES = 1.5


@dataclass(frozen=True)
class PointObservation:
    """One frame's view of the target: ``b`` (and ``a``, None for a single blob) in raw px, or why not.

    size: the target's size in the image, px (tag side, blob diameter, patch side); score: how well it
    matched (tag: 1; blob: its area, px²; patch: the correlation coefficient).
    """

    found: bool
    reason: str = ""
    detail: str = ""
    a: tuple[float, float] | None = None
    b: tuple[float, float] | None = None
    size: float = math.nan
    score: float = math.nan
    corners: np.ndarray | None = None


def _lost(detail: str) -> PointObservation:
    return PointObservation(False, LOST, detail)


def _clip_box(box: tuple[float, float, float, float], roi: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
    x0, y0, x1, y1 = box
    return (max(int(math.floor(x0)), roi[0]), max(int(math.floor(y0)), roi[1]),
            min(int(math.ceil(x1)), roi[2]), min(int(math.ceil(y1)), roi[3]))


class Locator:
    """Base of the locators: the region of interest, the search window and the last position."""

    #: frames must be decoded in colour
    colour = False

    def __init__(self, spec: TargetSpec, width: int, height: int):
        self.spec = spec
        self.roi = spec.roi if spec.roi is not None else (0, 0, width, height)
        self.width, self.height = width, height
        self._last: tuple[float, float] | None = None
        self._velocity = (0.0, 0.0)
        self._size = 0.0
        self._previous: tuple[tuple[int, int, int, int], np.ndarray] | None = None

    def window(self) -> tuple[int, int, int, int]:
        """Where to look first: around the predicted centre, else the whole region of interest."""
        if self._last is None or not self._size:
            return self.roi
        last = self._last
        cu = last[0] + self._velocity[0]
        cv = last[1] + self._velocity[1]
        half = WINDOW_SIZES * self._size + 2 * max(abs(self._velocity[0]), abs(self._velocity[1])) + 4
        box = _clip_box((cu - half, cv - half, cu + half, cv + half), self.roi)
        return box if box[2] - box[0] >= 8 and box[3] - box[1] >= 8 else self.roi

    def moved(self, centre: tuple[float, float], size: float) -> None:
        if self._last is not None:
            self._velocity = (centre[0] - self._last[0], centre[1] - self._last[1])
        self._last, self._size = centre, size

    def _duplicate(self, frame: np.ndarray, box: tuple[int, int, int, int]) -> bool:
        """The window shows what the previous frame showed there (``DUPLICATE_GREY``)."""
        x0, y0, x1, y1 = self.roi if self._last is None else box
        now = frame[y0:y1, x0:x1]
        prev, self._previous = self._previous, (box if self._last is not None else self.roi, frame.copy())
        if prev is None or prev[1].shape != frame.shape:
            return False
        before = prev[1][y0:y1, x0:x1]
        return bool(cv2.norm(now, before, cv2.NORM_L1) < DUPLICATE_GREY * now.size)

    def forget(self) -> None:
        self._last, self._velocity = None, (0.0, 0.0)

    def locate(self, frame: np.ndarray | None) -> PointObservation:
        """The target in one frame (grey, or BGR for a colour target); never raises on a bad frame."""
        if frame is None or not isinstance(frame, np.ndarray) or frame.shape[:2] != (self.height, self.width):
            self.forget()
            return PointObservation(False, CORRUPT, "no image of the camera's size (the decoder returned nothing)")
        box = self.window()
        # only a followed target can be seen not to change (an empty scene is "not found", not "repeated")
        if self._duplicate(frame, box) and self._last is not None:
            return PointObservation(False, REPEATED, "the previous frame again (a duplicated frame)")
        obs = self._find(frame, box)
        if not obs.found and box != self.roi:
            obs = self._find(frame, self.roi)
        if obs.found:
            assert obs.b is not None, "a found target has its point b"
            b = obs.b
            centre = b if obs.a is None else ((obs.a[0] + b[0]) / 2, (obs.a[1] + b[1]) / 2)
            self.moved(centre, obs.size)
        else:
            self.forget()
        return obs

    def _find(self, frame: np.ndarray, box: tuple[int, int, int, int]) -> PointObservation:
        raise NotImplementedError


def grey_of(frame: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame


class TagLocator(Locator):
    """A printed ArUco/AprilTag (OpenCV's ``cv2.aruco.ArucoDetector``, corners refined to sub-pixel)."""

    def __init__(self, spec: TargetSpec, width: int, height: int):
        super().__init__(spec, width, height)
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary_name(spec.dictionary)))
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        # the default stops at 0.1 px: 0.2° on a 60 px tag
        params.cornerRefinementMinAccuracy = 0.001
        params.cornerRefinementMaxIterations = 100
        # two adaptive-threshold passes (5 and 21 px) instead of three: a printed tag is high-contrast
        params.adaptiveThreshWinSizeMin, params.adaptiveThreshWinSizeMax, params.adaptiveThreshWinSizeStep = 5, 21, 16
        self.detector = cv2.aruco.ArucoDetector(dictionary, params)

    def _find(self, frame: np.ndarray, box: tuple[int, int, int, int]) -> PointObservation:
        x0, y0, x1, y1 = box
        corners, ids, _ = self.detector.detectMarkers(grey_of(frame)[y0:y1, x0:x1])
        if ids is None or len(ids) == 0:
            return _lost(f"no {self.spec.dictionary} tag in view")
        ids = ids.ravel()
        if self.spec.tag_id is not None:
            hits = np.flatnonzero(ids == self.spec.tag_id)
            if hits.size == 0:
                return _lost(f"tag {self.spec.tag_id} not in view (saw {sorted(int(i) for i in ids)})")
            k = int(hits[0])
        else:
            k = 0
        c = corners[k].reshape(4, 2).astype(float) + (x0, y0)
        # OpenCV's order: top-left, top-right, bottom-right, bottom-left (as printed). The tag's "down" from all
        # four sides: the left and right sides as they run, the top and bottom ones turned by 90°
        down = (c[3] - c[0] + c[2] - c[1]) / 2
        right = (c[1] - c[0] + c[2] - c[3]) / 2
        v = (down + np.array([-right[1], right[0]])) / 2
        centre = c.mean(axis=0)
        top, bottom = centre - v / 2, centre + v / 2
        side = float(np.mean(np.hypot(*(c - np.roll(c, 1, axis=0)).T)))
        return PointObservation(True, a=(float(top[0]), float(top[1])), b=(float(bottom[0]), float(bottom[1])),
                                size=side, score=1.0, corners=c)


class BlobLocator(Locator):
    """One blob (``count`` = 1) or two (``count`` = 2) of a colour (CIELAB distance) or of a brightness.

    Brightness: darker (or brighter) than a threshold set once from the region of interest of the first
    frame, halfway between its median grey and its darkest (brightest) 0.05 %. The blob's centre is
    the centroid of its outline, holes filled.
    """

    def __init__(self, spec: TargetSpec, width: int, height: int, count: int = 1):
        super().__init__(spec, width, height)
        self.count = count
        self.colour = spec.colour is not None
        self._lab: np.ndarray | None = None
        if spec.colour is not None:
            r, g, b = spec.colour
            pixel = np.array([[[b, g, r]]], dtype=np.uint8)
            self._lab = cv2.cvtColor(pixel, cv2.COLOR_BGR2Lab).reshape(3).astype(np.float32)
            room = np.array([3 * spec.tolerance * 255 / 100, spec.tolerance, spec.tolerance])
            self._lab_lo = np.clip(self._lab - room, 0, 255).astype(np.uint8)
            self._lab_hi = np.clip(self._lab + room, 0, 255).astype(np.uint8)
        self._threshold: float | None = None
        self._points: list[tuple[float, float]] | None = None
        self._blob_size = 0.0

    def mask(self, frame: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
        """Pixels of the target's colour or brightness inside ``box`` (uint8 0/255)."""
        x0, y0, x1, y1 = box
        if self._lab is not None:
            patch = frame[y0:y1, x0:x1]
            if patch.ndim != 3:
                patch = cv2.cvtColor(patch, cv2.COLOR_GRAY2BGR)
            # a box about the colour in OpenCV's 8-bit CIELAB (L scaled by 255/100, a and b offset by 128);
            # lightness gets three times the room: shading changes it across a curved bob, not the hue
            return cv2.inRange(cv2.cvtColor(patch, cv2.COLOR_BGR2Lab), self._lab_lo, self._lab_hi)
        grey = grey_of(frame)
        if self._threshold is None:
            rx0, ry0, rx1, ry1 = self.roi
            # halfway between the region's typical grey and its darkest (brightest) pixels: a target
            # darker (brighter) than everything around it, whatever else the region holds
            region = grey[ry0:ry1, rx0:rx1]
            extreme = np.percentile(region, 0.05 if self.spec.polarity == "dark" else 99.95)
            self._threshold = 0.5 * (float(np.median(region)) + float(extreme))
        kind = cv2.THRESH_BINARY_INV if self.spec.polarity == "dark" else cv2.THRESH_BINARY
        return cv2.threshold(grey[y0:y1, x0:x1], self._threshold, 255, kind)[1]

    def window(self) -> tuple[int, int, int, int]:
        if self.count == 2 and self._points is not None and self._last is not None:
            return self.roi  # two blobs are looked for each in its own window first (``_find``)
        return super().window()

    def _find(self, frame: np.ndarray, box: tuple[int, int, int, int]) -> PointObservation:
        if self.count == 2 and self._points is not None and self._last is not None:
            pair = self._find_each(frame)
            if pair is not None:
                return pair
        return self._find_in(frame, box)

    def _find_each(self, frame: np.ndarray) -> PointObservation | None:
        """Each of two followed blobs in a window around its last position (None: not both found whole)."""
        assert self._points is not None
        half = WINDOW_SIZES * self._blob_size + 2 * max(abs(self._velocity[0]), abs(self._velocity[1])) + 4
        found = []
        for pu, pv in self._points:
            box = _clip_box((pu - half, pv - half, pu + half, pv + half), self.roi)
            obs = self._find_in(frame, box, count=1)
            if not obs.found or obs.b is None:
                return None
            found.append(obs.b)
        pts = self._keep_identity(found)
        span = math.hypot(pts[1][0] - pts[0][0], pts[1][1] - pts[0][1])
        return PointObservation(True, a=pts[0], b=pts[1], size=span, score=1.0)

    def _find_in(self, frame: np.ndarray, box: tuple[int, int, int, int], count: int | None = None
                 ) -> PointObservation:
        count = count or self.count
        m = self.mask(frame, box)
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        _, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        areas = stats[1:, cv2.CC_STAT_AREA]
        order = np.argsort(areas)[::-1][:count]
        order = order[areas[order] >= MIN_BLOB_AREA]
        what = "colour" if self._lab is not None else f"{self.spec.polarity} brightness"
        if order.size < count:
            return _lost(f"{order.size} blob(s) of the target's {what} in view; expected {count}")
        x0, y0 = box[0], box[1]
        pts = [_filled_centre(labels, stats, 1 + int(k), x0, y0) for k in order]
        # the blob must be whole: one touching the window's border is cut (search the region instead)
        for k in order:
            bx, by, bw, bh = stats[1 + k, :4]
            if box != self.roi and (bx == 0 or by == 0 or bx + bw == m.shape[1] or by + bh == m.shape[0]):
                return _lost("the blob reaches the search window's border")
        size = float(2 * math.sqrt(float(areas[order].mean()) / math.pi))
        self._blob_size = size
        if count == 1:
            return PointObservation(True, b=pts[0], size=size, score=float(areas[order[0]]))
        pts = self._keep_identity(pts)
        span = math.hypot(pts[1][0] - pts[0][0], pts[1][1] - pts[0][1])
        return PointObservation(True, a=pts[0], b=pts[1], size=max(size, span), score=float(areas[order].min()))

    def _keep_identity(self, pts: list[tuple[float, float]]) -> list[tuple[float, float]]:
        """Which blob is a: the one nearer to a's last position (first time: the leftmost, then the upper)."""
        if self._points is None:
            pts = sorted(pts)
        else:
            pa = self._points[0]
            d0 = math.hypot(pts[0][0] - pa[0], pts[0][1] - pa[1])
            d1 = math.hypot(pts[1][0] - pa[0], pts[1][1] - pa[1])
            if d1 < d0:
                pts = [pts[1], pts[0]]
        self._points = pts
        return pts


def _filled_centre(labels: np.ndarray, stats: np.ndarray, k: int, x0: int, y0: int) -> tuple[float, float]:
    """Centre (px) of blob k with its holes filled: the area centroid of its outer contour. A highlight or a
    printed pattern inside a bob would otherwise pull the centre towards its other side as the light changes."""
    bx, by, bw, bh = (int(v) for v in stats[k, :4])
    sub = (labels[by:by + bh, bx:bx + bw] == k).astype(np.uint8)
    contours, _ = cv2.findContours(sub, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    m = cv2.moments(max(contours, key=cv2.contourArea))
    if m["m00"] <= 0:
        ys, xs = np.nonzero(sub)
        return float(xs.mean() + bx + x0), float(ys.mean() + by + y0)
    # contour moments treat pixel centres as the polygon's vertices: the outline runs half a pixel inside
    return float(m["m10"] / m["m00"] + bx + x0), float(m["m01"] / m["m00"] + by + y0)


class PatchLocator(Locator):
    """The body's texture inside the region of interest of the first frame, followed by enhanced correlation
    alignment (a Euclidean motion: the in-plane rotation and the shift of the patch).

    A region of more than ``MAX_PATCH_PIXELS`` is aligned on the frame shrunk by a whole factor (pixel
    averaging): ECC's cost grows with the patch's area, its angle's precision hardly does once the patch holds
    that many pixels of texture."""

    def __init__(self, spec: TargetSpec, width: int, height: int):
        super().__init__(spec, width, height)
        self._template: np.ndarray | None = None
        self._scale = 1  # the frame's shrink factor for the alignment
        self._warp = np.eye(2, 3, dtype=np.float32)
        self._criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-5)
        self._step = np.zeros((2, 3), dtype=np.float32)  # the last frame-to-frame change of the warp

    def window(self) -> tuple[int, int, int, int]:
        return self.roi  # the patch keeps its own window (around its last pose)

    def forget(self) -> None:
        super().forget()
        self._step = np.zeros((2, 3), dtype=np.float32)  # lost: start again from the last pose, not its motion

    def _start(self, grey: np.ndarray) -> None:
        """The template from the first frame's region of interest, shrunk to at most ``MAX_PATCH_PIXELS``."""
        x0, y0, x1, y1 = self.roi
        self._scale = max(1, math.ceil(math.sqrt((x1 - x0) * (y1 - y0) / MAX_PATCH_PIXELS)))
        self._template = _shrink(grey[y0:y1, x0:x1], self._scale)
        self._warp = np.array([[1, 0, x0], [0, 1, y0]], dtype=np.float32)

    def _search_window(self, warp: np.ndarray, h: int, w: int) -> tuple[int, int, int, int]:
        """The part of the frame ECC reads: the patch where ``warp`` puts it and half its size around it, px."""
        margin = int(0.5 * max(h, w)) + 8
        corners = np.array([[0, 0, 1], [w, 0, 1], [0, h, 1], [w, h, 1]], dtype=np.float32) @ warp.T
        return (max(int(corners[:, 0].min()) - margin, 0), max(int(corners[:, 1].min()) - margin, 0),
                min(int(corners[:, 0].max()) + margin, self.width), min(int(corners[:, 1].max()) + margin, self.height))

    def _find(self, frame: np.ndarray, box: tuple[int, int, int, int]) -> PointObservation:
        grey = grey_of(frame)
        if self._template is None:
            self._start(grey)
        assert self._template is not None
        s = self._scale
        h, w = (s * n for n in self._template.shape)  # the full-resolution pixels the template covers
        # a window of the frame around where the patch was (ECC's cost grows with the image it reads),
        # starting from where its motion takes it (fewer iterations)
        warp = self._warp + self._step
        wx0, wy0, wx1, wy1 = self._search_window(warp, h, w)
        if wx1 - wx0 < 8 * s or wy1 - wy0 < 8 * s:
            return _lost("the patch left the image")
        local = warp.copy()
        local[0, 2] -= wx0
        local[1, 2] -= wy0
        try:
            score, level = cv2.findTransformECC(self._template, _shrink(grey[wy0:wy1, wx0:wx1], s),
                                                _to_level(local, s), cv2.MOTION_EUCLIDEAN, self._criteria,
                                                None, 5)  # type: ignore[call-overload]
        except cv2.error:
            return _lost("the patch's alignment did not converge")
        if not score >= MIN_PATCH_CORRELATION:
            return _lost(f"the patch matches the frame with a correlation of only {score:.2f}")
        local = _from_level(level, s)
        local[0, 2] += wx0
        local[1, 2] += wy0
        self._step = local - self._warp
        self._warp = local
        centre = np.array([w / 2, h / 2, 1.0])
        below = np.array([w / 2, h, 1.0])
        a, b = local @ centre, local @ below
        return PointObservation(True, a=(float(a[0]), float(a[1])), b=(float(b[0]), float(b[1])),
                                size=float(max(h, w)), score=float(score))


def _shrink(img: np.ndarray, s: int) -> np.ndarray:
    """``img`` as float32, shrunk by the whole factor s: each pixel the mean of an s×s block (rows and columns
    beyond the last whole block dropped)."""
    if s == 1:
        return img.astype(np.float32)
    h, w = img.shape[0] // s, img.shape[1] // s
    return cv2.resize(img[:h * s, :w * s], (w, h), interpolation=cv2.INTER_AREA).astype(np.float32)


def _to_level(warp: np.ndarray, s: int) -> np.ndarray:
    """A Euclidean warp (template px → frame px) on the images shrunk by s. Pixel i of the shrunk image is
    centred on s·i + (s − 1)/2 of the full one: the rotation is the same, the shift moves."""
    c = (s - 1) / 2
    out = warp.copy()
    out[:, 2] = (warp[:, :2] @ np.array([c, c], dtype=np.float32) + warp[:, 2] - c) / s
    return out


def _from_level(warp: np.ndarray, s: int) -> np.ndarray:
    """The inverse of ``_to_level``: the full-resolution warp of one found on the images shrunk by s."""
    c = (s - 1) / 2
    out = warp.copy()
    out[:, 2] = s * warp[:, 2] + c - warp[:, :2] @ np.array([c, c], dtype=np.float32)
    return out


def make_locator(spec: TargetSpec, width: int, height: int) -> Locator:
    """The locator of a target kind (not the edge, which has ``MarkerTracker``)."""
    if spec.kind == "tag":
        return TagLocator(spec, width, height)
    if spec.kind == "blob":
        return BlobLocator(spec, width, height, 1)
    if spec.kind == "blobs":
        return BlobLocator(spec, width, height, 2)
    if spec.kind == "patch":
        return PatchLocator(spec, width, height)
    raise ValueError(f"no point locator for target kind {spec.kind!r}")
