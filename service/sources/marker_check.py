"""One frame checked for the marker: where it is, at what angle, drawn on the frame. What the technician sees
from `moi camera-check` and on the web page's camera set-up view.

The image marks the search window, every row's edge point, the fitted edge line and the principal point; the
facts give the marker's offset from the principal point, the edge's tilt and the angle. With the pendulum at rest
and the camera on the line to the swing axis, the marker sits on the principal point with no tilt; an offset
means the optical axis is yawed (the implied yaw is given).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the vision modules load OpenCV: imported where used
    import numpy as np

    from measurement.vision.config import CameraConfig
    from measurement.vision.locate import MarkerObservation


def _annotate(img: np.ndarray, obs: MarkerObservation, config: CameraConfig, lines: list[str]) -> np.ndarray:
    import cv2
    import numpy as np

    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    cam = config.camera
    c = (int(round(cam.cx)), int(round(cam.cy)))
    cv2.drawMarker(out, c, (255, 255, 0), cv2.MARKER_CROSS, 25, 1)
    if obs.roi is not None:
        r0, r1, c0, c1 = obs.roi
        cv2.rectangle(out, (c0, r0), (c1 - 1, r1 - 1), (0, 255, 255), 1)
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
        cv2.polylines(out, [pts], False, (0, 0, 255), 1)
        cv2.drawMarker(out, (int(round(obs.u)), int(round(obs.v))), (0, 0, 255), cv2.MARKER_DIAMOND, 12, 1)
    if lines:
        # a dark box keeps the text readable on any scene
        width = max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0][0] for t in lines[:4])
        cv2.rectangle(out, (2, 2), (14 + width, 8 + 18 * len(lines[:4])), (0, 0, 0), -1)
    for i, text in enumerate(lines[:4]):
        cv2.putText(out, text, (8, 18 + 18 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def check_image(img: np.ndarray, config: CameraConfig) -> tuple[np.ndarray, dict, list[str]]:
    """Find the marker in a grey frame: (the annotated BGR image, the facts, the lines of text drawn on it).
    What the technician sees here and on the web page's set-up view."""
    from measurement.vision.geometry import angle_from_normalised
    from measurement.vision.locate import MarkerTracker

    obs = MarkerTracker(config.camera).locate(img, keep_points=True)
    report: dict = {"found": obs.found}
    if obs.found:
        theta = float(angle_from_normalised(obs.x, config.marker))
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
    else:
        report.update({"reason": obs.reason, "detail": obs.detail})
        lines = [f"marker NOT found: {obs.detail or obs.reason}"]
    return _annotate(img, obs, config, lines), report, lines
