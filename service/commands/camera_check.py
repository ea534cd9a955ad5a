"""`moi camera-check [VIDEO|DEVICE]`: the first frame with the target found, and how well the first seconds track.

For the technician setting the camera up, and for a user about to identify a
video: the PNG shows the first frame with the region of interest (yellow),
the target found (red: the edge line, or the tag's outline and the body
vector's ends), the pivot (cyan) and the angle axis (green: the direction
whose turn is the swing angle). The text and ``--json`` give the target's
position and angle, and the share of the frames of the first ``--seconds``
in which it was tracked, judged by the rule ``moi identify`` applies
(``measurement.vision.quality``): below it, exit status 2, as identify would
refuse. For the edge on a cylinder, the marker's offset from the principal
point, its tilt and the yaw implied if it is at rest are given too.

Frames from: VIDEO (a video file, an image, an image folder) or DEVICE
(``/dev/videoN``), also as ``--source``/``--device``; else the mock camera
(the camera file's target rendered at ``--angle``), which needs no hardware.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from typing import TYPE_CHECKING, Any

from measurement.errors import VisionError

from service.config.camera import read_camera
from service.devices.defaults import demo_camera
from service.errors import InputFileError

if TYPE_CHECKING:  # the vision modules load OpenCV: imported where used, not for `moi --help`
    import numpy as np

    from measurement.vision.config import CameraConfig
    from measurement.vision.locate import MarkerObservation
    from measurement.vision.locators import PointObservation
    from measurement.vision.pipeline import Tracking


#: frames grabbed from a live camera before the one measured (exposure and gain settle)
SETTLE_FRAMES = 5
#: seconds of a video or camera tracked for the share reported
DEFAULT_SECONDS = 3.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="?", metavar="VIDEO|DEVICE",
                   help="a video file, image or image folder, or a V4L2 camera such as /dev/video0")
    p.add_argument("--camera", metavar="CAM.toml", help="camera file (default: the demo camera, 640×480, fx 600 px)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--source", metavar="FILE", help="an image, a video file or an image folder instead of a camera")
    g.add_argument("--device", metavar="DEV", help="V4L2 camera, e.g. /dev/video0 (default: the mock camera)")
    p.add_argument("--frame", type=int, default=0, metavar="N", help="with a video/folder: frame number drawn (default 0)")
    p.add_argument("--seconds", type=float, default=DEFAULT_SECONDS, metavar="S",
                   help=f"frames of the first S seconds tracked for the share (default {DEFAULT_SECONDS:g})")
    p.add_argument("--angle", type=float, default=0.0, metavar="DEG",
                   help="mock camera only: the target's angle, degrees (default 0, at rest)")
    p.add_argument("--out", default="camera-check.png", metavar="FILE.png", help="annotated image (default camera-check.png)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the text")


def _device_of(args: argparse.Namespace) -> tuple[str | None, str | None]:
    """(file source, device) from the positional argument or the options."""
    if args.input:
        if args.source or args.device:
            raise InputFileError("give the video or device once: as VIDEO|DEVICE or with --source/--device")
        is_device = args.input.startswith("/dev/") or args.input.isdigit()
        return (None, args.input) if is_device else (args.input, None)
    return args.source, args.device


def _grab(args: argparse.Namespace, config: CameraConfig) -> tuple[np.ndarray, str, Tracking | None]:
    """The frame to draw (grey, or BGR for a colour target), where it came from, and the tracking of the first
    ``--seconds`` (None for a still image or the mock camera)."""
    import cv2
    import numpy as np

    from measurement.vision.locate import to_grey

    source, device = _device_of(args)
    if source:
        path = Path(source)
        if not path.exists():
            raise InputFileError(f"source {str(path)!r} not found")
        from drivers.video_file import IMAGE_SUFFIXES, FrameSource

        if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES:
            img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if img is None:
                raise InputFileError(f"image {str(path)!r} cannot be decoded")
            if img.dtype != np.uint8:
                raise InputFileError(f"image {str(path)!r} has {img.dtype} pixels; expected 8-bit")
            if not config.target.needs_colour:
                img = to_grey(img)
            elif img.ndim == 2:
                img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
            return img[..., :3] if img.ndim == 3 else img, str(path), None
        if args.frame < 0:
            raise InputFileError(f"--frame must be >= 0, got {args.frame}")
        if not args.seconds > 0:
            raise InputFileError(f"--seconds must be > 0, got {args.seconds}")
        from service.sources.video import track_source

        drawn = None
        for n, (_, img) in enumerate(FrameSource(path, config, colour=config.target.needs_colour)):
            if n == args.frame:
                if img is None:
                    raise InputFileError(f"{path}: frame {n} cannot be decoded")
                drawn = img
                break
        if drawn is None:
            raise InputFileError(f"{path}: has no frame {args.frame}")
        tracking, _ = track_source(path, config, seconds=args.seconds)
        return drawn, f"{path} frame {args.frame}", tracking
    from drivers.camera import open_camera

    if device:
        from measurement.vision.pipeline import Tracking, tracker_for

        dev = int(device) if device.isdigit() else device
        with open_camera(config, dev) as cam:
            frame = cam.grab()
            for _ in range(SETTLE_FRAMES - 1):
                frame = cam.grab()
            tracker, tracking = tracker_for(config), Tracking()
            first = frame
            while True:
                tracking.add(frame.t - first.t, tracker.locate(frame.image))
                if frame.t - first.t >= args.seconds:
                    break
                frame = cam.grab()
            return first.image, f"camera {device}", tracking
    angle = math.radians(args.angle)
    with open_camera(config, angle_source=lambda t: angle, clock=lambda: 0.0, seed=0) as cam:
        return cam.grab().image, f"mock camera, target at {args.angle:g}°", None


def _point(p: tuple[float, float]) -> tuple[int, int]:
    return int(round(p[0])), int(round(p[1]))


def _annotate(img: np.ndarray, obs: MarkerObservation | PointObservation, config: CameraConfig, lines: list[str],
              pivot: tuple[float, float] | None = None) -> np.ndarray:
    import cv2
    import numpy as np

    from measurement.vision.locators import PointObservation

    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
    cam = config.camera
    roi = config.target.roi
    if roi is not None:
        cv2.rectangle(out, (roi[0], roi[1]), (roi[2] - 1, roi[3] - 1), (0, 255, 255), 1)
    if isinstance(obs, PointObservation):
        if obs.corners is not None:
            cv2.polylines(out, [np.round(obs.corners).astype(np.int32).reshape(-1, 1, 2)], True, (0, 0, 255), 1)
        start = obs.a if obs.a is not None else pivot
        if pivot is not None:
            cv2.drawMarker(out, _point(pivot), (255, 255, 0), cv2.MARKER_CROSS, 25, 2)
        if obs.found and obs.b is not None:
            cv2.drawMarker(out, _point(obs.b), (0, 0, 255), cv2.MARKER_DIAMOND, 12, 2)
            if obs.a is not None:
                cv2.drawMarker(out, _point(obs.a), (0, 0, 255), cv2.MARKER_DIAMOND, 12, 2)
            if start is not None:
                # the angle axis: the body vector, drawn long enough to see its direction
                du, dv = obs.b[0] - start[0], obs.b[1] - start[1]
                k = max(1.0, 60.0 / max(math.hypot(du, dv), 1e-9))
                length = k * math.hypot(du, dv)
                cv2.arrowedLine(out, _point(start), _point((start[0] + k * du, start[1] + k * dv)), (0, 255, 0), 2,
                                tipLength=min(0.3, 15.0 / max(length, 1.0)))
    else:
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
        width = max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0][0] for t in lines[:5])
        cv2.rectangle(out, (2, 2), (14 + width, 8 + 18 * len(lines[:5])), (0, 0, 0), -1)
    for i, text in enumerate(lines[:5]):
        cv2.putText(out, text, (8, 18 + 18 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
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
    from measurement.vision.pipeline import tracker_for

    from measurement.vision.locators import Locator

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


def _share(tracking: Tracking, config: CameraConfig, seconds: float) -> tuple[dict, list[str], str]:
    """The share of the first seconds tracked, judged by identify's rule: (facts, lines, refusal or '')."""
    from measurement.vision.body import fit_pivot
    from measurement.vision.quality import MIN_SHARE

    decoded = max(len(tracking.decoded_times) - tracking.repeated, len(tracking.t))
    share = len(tracking.t) / decoded if decoded else 0.0
    facts: dict = {"seconds": seconds, "frames_checked": decoded, "frames_tracked": len(tracking.t),
                   "repeated_frames": tracking.repeated, "tracked_share": round(share, 4),
                   "min_tracked_share": MIN_SHARE, "failures": dict(tracking.reasons)}
    lines = [f"first {seconds:g} s: target tracked in {len(tracking.t)} of {decoded} frames ({100 * share:.0f} %)"]
    refusal = ""
    if share < MIN_SHARE:
        refusal = (f"the target was tracked in {100 * share:.0f} % of the first {seconds:g} s "
                   f"({tracking.reasons_text() or 'no frames'}); `moi identify` needs {100 * MIN_SHARE:.0f} %")
    if not config.edge and tracking.b and tracking.a and tracking.a[0] is None and config.target.pivot is None:
        import numpy as np

        try:
            p = fit_pivot(np.asarray(tracking.b, dtype=float), "first seconds")
            facts["pivot_px"] = [round(p.u, 2), round(p.v, 2)]
        except VisionError as e:
            facts["pivot_note"] = str(e)
    return facts, lines, refusal


def run(args: argparse.Namespace) -> int:
    import cv2

    config = read_camera(args.camera) if args.camera else demo_camera()
    img, where, tracking = _grab(args, config)
    facts: dict = {}
    extra: list[str] = []
    refusal = ""
    if tracking is not None:
        facts, extra, refusal = _share(tracking, config, args.seconds)
    pivot = (float(facts["pivot_px"][0]), float(facts["pivot_px"][1])) if "pivot_px" in facts else None
    annotated, found, lines = check_image(img, config, pivot, extra)
    report: dict = {"source": where, "png": args.out, **found, **facts}
    if refusal:
        report["refusal"] = refusal
    if not cv2.imwrite(args.out, annotated):
        raise InputFileError(f"cannot write {args.out!r} (directory missing or not writable, or not a .png name)")
    if args.json:
        sys.stdout.write(json.dumps(report, allow_nan=False) + "\n")
    else:
        print(f"camera-check: {where}")
        for line in lines + extra:
            print(f"  {line}")
        if refusal:
            print(f"  NOT ready: {refusal}")
        print(f"  annotated image written to {args.out}")
    if not found["found"]:
        what = "marker" if config.edge else config.target.kind
        raise VisionError(f"{what} not found in {where}: {found.get('detail') or found.get('reason')} (see {args.out})")
    if refusal:
        raise VisionError(f"{where}: {refusal} (see {args.out})")
    return 0
