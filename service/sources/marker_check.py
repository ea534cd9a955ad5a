"""One frame checked for the target: where it is, at what angle, drawn on the frame. What the technician sees
from `moi camera-check` and on the web page's camera set-up view.

The image marks the region of interest (yellow), the target found (red: the edge line, or the tag's outline and
the body vector's ends), the pivot (cyan) and the angle axis (green). For the edge on a cylinder the facts give the
marker's offset from the principal point, the edge's tilt and the angle: with the pendulum at rest and the camera
on the line to the swing axis, the marker sits on the principal point with no tilt; an offset means the optical
axis is yawed (the implied yaw is given). Facts are JSON-ready: a number that is not finite is null.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the vision modules load OpenCV: imported where used
    import numpy as np

    from measurement.vision.config import CameraConfig
    from measurement.vision.locate import MarkerObservation
    from measurement.vision.locators import PointObservation


#: the drawing's proportions on a 640×480 frame; other frames scale them with their size
BASE_WIDTH, BASE_HEIGHT = 640, 480
FONT_SCALE = 0.5          # OpenCV's Hershey simplex: about 11 px tall capitals at 640×480
LINE_STEP = 18            # px from one text line to the next at 640×480
#: least font scale: smaller Hershey text cannot be read on a small frame
MIN_FONT_SCALE = 0.35
#: lines of text drawn on the frame (the rest are in the printed report)
MAX_LINES = 5


def _point(p: tuple[float, float]) -> tuple[int, int]:
    return int(round(p[0])), int(round(p[1]))


def drawing_scale(width: int, height: int) -> float:
    """How much larger than on a 640×480 frame the marks and text are drawn on a width×height frame: a
    1280×720 phone frame's text is as large a part of the picture, and as readable once shown on a screen."""
    return min(width / BASE_WIDTH, height / BASE_HEIGHT)


def _text(out: np.ndarray, lines: list[str]) -> None:
    """The lines in white on a dark box (readable on any scene), scaled with the frame and shrunk to its width,
    never below a legible size (a line too long for a small frame is cut at its edge)."""
    import cv2

    lines = lines[:MAX_LINES]
    if not lines:
        return
    h, w = out.shape[:2]
    scale = max(MIN_FONT_SCALE, FONT_SCALE * drawing_scale(w, h))
    k = scale / FONT_SCALE
    thick = max(1, int(round(k)))
    widest = max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0] for t in lines)
    margin = int(round(8 * k))
    if widest > w - 2 * margin:
        # a narrow (portrait) frame: the lines shrink to fit its width, down to what can still be read
        scale = max(MIN_FONT_SCALE, scale * (w - 2 * margin) / widest)
        k = scale / FONT_SCALE
        thick = max(1, int(round(k)))
        widest = max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0] for t in lines)
        margin = int(round(8 * k))
    step = int(round(LINE_STEP * k))
    cv2.rectangle(out, (2, 2), (min(w - 1, 2 * margin - 2 + widest), margin + step * len(lines)), (0, 0, 0), -1)
    for i, text in enumerate(lines):
        cv2.putText(out, text, (margin, margin + int(round(10 * k)) + step * i), cv2.FONT_HERSHEY_SIMPLEX, scale,
                    (255, 255, 255), thick, cv2.LINE_AA)


def _annotate(img: np.ndarray, obs: MarkerObservation | PointObservation, config: CameraConfig, lines: list[str],
              pivot: tuple[float, float] | None = None) -> np.ndarray:
    import cv2
    import numpy as np

    from measurement.vision.locators import PointObservation

    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
    cam = config.camera
    k = drawing_scale(out.shape[1], out.shape[0])
    thin, bold = max(1, int(round(k))), max(2, int(round(2 * k)))
    cross, diamond = int(round(25 * k)), int(round(12 * k))
    roi = config.target.roi
    if roi is not None:
        cv2.rectangle(out, (roi[0], roi[1]), (roi[2] - 1, roi[3] - 1), (0, 255, 255), thin)
    if isinstance(obs, PointObservation):
        if obs.corners is not None:
            cv2.polylines(out, [np.round(obs.corners).astype(np.int32).reshape(-1, 1, 2)], True, (0, 0, 255), thin)
        start = obs.a if obs.a is not None else pivot
        if pivot is not None:
            cv2.drawMarker(out, _point(pivot), (255, 255, 0), cv2.MARKER_CROSS, cross, bold)
        if obs.found and obs.b is not None:
            cv2.drawMarker(out, _point(obs.b), (0, 0, 255), cv2.MARKER_DIAMOND, diamond, bold)
            if obs.a is not None:
                cv2.drawMarker(out, _point(obs.a), (0, 0, 255), cv2.MARKER_DIAMOND, diamond, bold)
            if start is not None:
                # the angle axis: the body vector, drawn long enough to see its direction
                du, dv = obs.b[0] - start[0], obs.b[1] - start[1]
                stretch = max(1.0, 60.0 * k / max(math.hypot(du, dv), 1e-9))
                length = stretch * math.hypot(du, dv)
                cv2.arrowedLine(out, _point(start), _point((start[0] + stretch * du, start[1] + stretch * dv)),
                                (0, 255, 0), bold, tipLength=min(0.3, 15.0 * k / max(length, 1.0)))
    else:
        c = (int(round(cam.cx)), int(round(cam.cy)))
        cv2.drawMarker(out, c, (255, 255, 0), cv2.MARKER_CROSS, cross, thin)
        if obs.roi is not None:
            r0, r1, c0, c1 = obs.roi
            cv2.rectangle(out, (c0, r0), (c1 - 1, r1 - 1), (0, 255, 255), thin)
        if obs.found:
            if obs.points is not None:
                for u, v in zip(*obs.points):
                    out[int(round(v)), min(max(int(round(u)), 0), cam.width - 1)] = (0, 255, 0)
            # the fitted edge line, drawn through the lens model over the marker's rows
            if obs.points is not None and obs.points[0].size:
                y_pts = cam.undistort(*obs.points)[1]
                ys = np.linspace(float(y_pts.min()), float(y_pts.max()), 40)
            else:
                ys = np.full(2, obs.y_ref)
            us, vs = cam.distort(obs.x + obs.slope * (ys - obs.y_ref), ys)
            pts = np.stack([us, vs], axis=1).round().astype(np.int32).reshape(-1, 1, 2)
            cv2.polylines(out, [pts], False, (0, 0, 255), thin)
            cv2.drawMarker(out, (int(round(obs.u)), int(round(obs.v))), (0, 0, 255), cv2.MARKER_DIAMOND, diamond, thin)
    _text(out, lines)
    return out


def _finite(value: Any) -> Any:
    """JSON has no NaN: a non-finite number is null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def check_image(img: np.ndarray, config: CameraConfig, pivot: tuple[float, float] | None = None,
                extra: list[str] | None = None) -> tuple[np.ndarray, dict, list[str]]:
    """Find the target in one frame: (the annotated BGR image, the facts, the lines of text about the frame).
    What the technician sees here and on the web page's set-up view. pivot: a single blob's pivot (px), when
    known (given in the camera file or found from the first seconds' arc); extra: more lines drawn."""
    if not config.edge:
        return _check_points(img, config, pivot or config.target.pivot, extra or [])
    from measurement.vision.geometry import angle_from_normalised
    from measurement.vision.locate import MarkerTracker, to_grey

    grey = to_grey(img)
    obs = MarkerTracker(config.camera).locate(grey, keep_points=True)
    report: dict = {"target": "edge", "found": obs.found}
    if obs.found:
        theta = float(angle_from_normalised(obs.x, config.cylinder))
        offset_px = obs.x * config.camera.fx
        # at rest, a marker facing a camera on the line to the axis is seen on the optical axis
        implied_yaw = -math.degrees(math.atan(obs.x))
        report.update({
            "u_px": obs.u, "v_px": obs.v, "offset_px": offset_px, "tilt_deg": obs.tilt_deg, "rows": obs.rows,
            "line_rms_px": obs.residual, "edge_strength_grey": obs.contrast, "angle_deg": math.degrees(theta),
            "implied_yaw_deg_if_at_rest": implied_yaw,
        })
        lines = [f"marker at u={obs.u:.2f} v={obs.v:.1f} px ({offset_px:+.1f} px from centre)",
                 f"angle {math.degrees(theta):+.3f} deg, edge tilt {obs.tilt_deg:+.2f} deg",
                 f"{obs.rows} rows, line RMS {obs.residual:.3f} px, edge strength {obs.contrast:.0f}",
                 f"if at rest: camera yaw {implied_yaw:+.2f} deg"]
        if not math.isfinite(theta):
            # what identify will say of this edge: it cannot lie where the camera file's cylinder is seen
            report.update({"found": False, "reason": "marker_lost",
                           "detail": f"the edge lies beyond the cylinder's silhouette for radius {config.cylinder.radius:g} m "
                                     f"and distance {config.cylinder.distance:g} m in the camera file"})
            lines[1] = f"angle: none ({report['detail']})"
    else:
        report.update({"reason": obs.reason, "detail": obs.detail})
        lines = [f"marker NOT found: {obs.detail or obs.reason}"]
    return _annotate(grey, obs, config, lines + (extra or [])), {k: _finite(v) for k, v in report.items()}, lines


def _check_points(img: np.ndarray, config: CameraConfig, pivot: tuple[float, float] | None, extra: list[str]
                  ) -> tuple[np.ndarray, dict, list[str]]:
    from measurement.vision.body import provisional_angle
    from measurement.vision.locators import Locator
    from measurement.vision.pipeline import tracker_for

    spec = config.target
    locator = tracker_for(config)
    assert isinstance(locator, Locator), "a target other than the edge has a point locator"
    obs = locator.locate(img)
    report: dict = {"target": spec.kind, "view": spec.view, "found": obs.found}
    if obs.found:
        assert obs.b is not None, "a found target has its point b"
        theta = provisional_angle(obs, pivot)
        report.update({"b_px": list(obs.b), "size_px": obs.size})
        if obs.a is not None:
            report["a_px"] = list(obs.a)
        if pivot is not None:
            report["pivot_px"] = list(pivot)
        report["angle_deg"] = math.degrees(theta) if math.isfinite(theta) else None
        where = f"at u={obs.b[0]:.1f} v={obs.b[1]:.1f} px" + (f" and u={obs.a[0]:.1f} v={obs.a[1]:.1f} px" if obs.a else "")
        lines = [f"{spec.kind} {where}, size {obs.size:.0f} px",
                 (f"angle {math.degrees(theta):+.3f} deg (the body vector from straight down)"
                  if math.isfinite(theta) else "angle: the pivot comes from the swing's arc (or [target] pivot)")]
    else:
        report.update({"reason": obs.reason, "detail": obs.detail})
        lines = [f"{spec.kind} NOT found: {obs.detail or obs.reason}"]
    return _annotate(img, obs, config, lines + extra, pivot), {k: _finite(v) for k, v in report.items()}, lines
