"""`moi camera-check`: grab one frame, find the marker, show where and at what angle, write a PNG.

For the technician setting the camera up: the PNG marks the search window,
every row's edge point, the fitted edge line and the principal point; the
text gives the marker's offset from the principal point, the edge's tilt
and the angle. With the pendulum at rest and the camera on the line to the
swing axis, the marker should sit on the principal point with no tilt; an
offset means the optical axis is yawed (the implied yaw is printed).

Frame from: ``--source`` (an image, a video file or an image folder),
``--device`` (a V4L2 camera), else the mock camera (the marker rendered at
``--angle``), which needs no hardware.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from typing import TYPE_CHECKING

from measurement.errors import VisionError

from service.config.camera import read_camera
from service.devices.defaults import demo_camera
from service.errors import InputFileError

if TYPE_CHECKING:  # the vision modules load OpenCV: imported where used, not for `moi --help`
    import numpy as np

    from measurement.vision.config import CameraConfig
    from measurement.vision.locate import MarkerObservation


#: frames grabbed from a live camera before the one measured (exposure and gain settle)
SETTLE_FRAMES = 5


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--camera", metavar="CAM.toml", help="camera file (default: the demo camera, 640×480, fx 600 px)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--source", metavar="FILE", help="an image, a video file or an image folder instead of a camera")
    g.add_argument("--device", metavar="DEV", help="V4L2 camera, e.g. /dev/video0 (default: the mock camera)")
    p.add_argument("--frame", type=int, default=0, metavar="N", help="with --source video/folder: frame number (default 0)")
    p.add_argument("--angle", type=float, default=0.0, metavar="DEG",
                   help="mock camera only: the marker's angle, degrees (default 0, at rest)")
    p.add_argument("--out", default="camera-check.png", metavar="FILE.png", help="annotated image (default camera-check.png)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the text")


def _grab(args: argparse.Namespace, config: CameraConfig) -> tuple[np.ndarray, str]:
    import cv2
    import numpy as np

    from measurement.vision.locate import to_grey

    if args.source:
        path = Path(args.source)
        if not path.exists():
            raise InputFileError(f"source {str(path)!r} not found")
        from drivers.video_file import IMAGE_SUFFIXES, FrameSource

        if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES:
            img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if img is None:
                raise InputFileError(f"image {str(path)!r} cannot be decoded")
            if img.dtype != np.uint8:
                raise InputFileError(f"image {str(path)!r} has {img.dtype} pixels; expected 8-bit")
            return to_grey(img), str(path)
        if args.frame < 0:
            raise InputFileError(f"--frame must be >= 0, got {args.frame}")
        for n, (_, img) in enumerate(FrameSource(path, config)):
            if n == args.frame:
                if img is None:
                    raise InputFileError(f"{path}: frame {n} cannot be decoded")
                return img, f"{path} frame {n}"
        raise InputFileError(f"{path}: has no frame {args.frame}")
    from drivers.camera import open_camera

    if args.device:
        device = int(args.device) if args.device.isdigit() else args.device
        with open_camera(config, device) as cam:
            frame = cam.grab()
            for _ in range(SETTLE_FRAMES - 1):
                frame = cam.grab()
            return frame.image, f"camera {args.device}"
    angle = math.radians(args.angle)
    with open_camera(config, angle_source=lambda t: angle, clock=lambda: 0.0, seed=0) as cam:
        return cam.grab().image, f"mock camera, marker at {args.angle:g}°"


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


def run(args: argparse.Namespace) -> int:
    import cv2

    config = read_camera(args.camera) if args.camera else demo_camera()
    img, where = _grab(args, config)
    annotated, facts, lines = check_image(img, config)
    report: dict = {"source": where, "png": args.out, **facts}
    if not cv2.imwrite(args.out, annotated):
        raise InputFileError(f"cannot write {args.out!r} (directory missing or not writable, or not a .png name)")
    if args.json:
        sys.stdout.write(json.dumps(report) + "\n")
    else:
        print(f"camera-check: {where}")
        for line in lines:
            print(f"  {line}")
        print(f"  annotated image written to {args.out}")
    if not facts["found"]:
        raise VisionError(f"marker not found in {where}: {facts['detail'] or facts['reason']} (see {args.out})")
    return 0
