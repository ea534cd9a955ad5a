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
from typing import TYPE_CHECKING

from measurement.errors import VisionError
from service.errors import InputFileError
from service.settings.defaults import demo_camera
from service.sources.camera import read_camera
from service.sources.marker_check import check_image

if TYPE_CHECKING:  # the vision modules load OpenCV: imported where used, not for `moi --help`
    import numpy as np

    from measurement.vision.config import CameraConfig
    from measurement.vision.pipeline import Tracking
    from measurement.vision.quality import Motion


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
    source, device = _device_of(args)
    if source:
        path = Path(source)
        if not path.exists():
            raise InputFileError(f"source {str(path)!r} not found")
        from drivers.video_file import IMAGE_SUFFIXES

        if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES:
            return _still(path, config), str(path), None
        return _from_video(path, args, config)
    from drivers.camera import open_camera

    if device:
        return _from_device(device, args, config)
    angle = math.radians(args.angle)
    with open_camera(config, angle_source=lambda t: angle, clock=lambda: 0.0, seed=0) as cam:
        return cam.grab().image, f"mock camera, target at {args.angle:g}°", None


def _still(path: Path, config: CameraConfig) -> np.ndarray:
    """An image file as the target's tracker reads it: grey, or BGR for a colour target."""
    import cv2
    import numpy as np

    from measurement.vision.locate import to_grey

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputFileError(f"image {str(path)!r} cannot be decoded")
    if img.dtype != np.uint8:
        raise InputFileError(f"image {str(path)!r} has {img.dtype} pixels; expected 8-bit")
    if not config.target.needs_colour:
        img = to_grey(img)
    elif img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    return img[..., :3] if img.ndim == 3 else img


def _from_video(path: Path, args: argparse.Namespace, config: CameraConfig) -> tuple[np.ndarray, str, Tracking]:
    """Frame ``--frame`` of a video or image folder, and the tracking of its first ``--seconds``."""
    from drivers.video_file import FrameSource
    from service.sources.video import track_source

    if args.frame < 0:
        raise InputFileError(f"--frame must be >= 0, got {args.frame}")
    if not args.seconds > 0:
        raise InputFileError(f"--seconds must be > 0, got {args.seconds}")
    drawn = None
    with FrameSource(path, config, colour=config.target.needs_colour) as frames:
        for n, (_, img) in enumerate(frames):
            if n == args.frame:
                if img is None:
                    raise InputFileError(f"{path}: frame {n} cannot be decoded")
                drawn = img
                break
    if drawn is None:
        raise InputFileError(f"{path}: has no frame {args.frame}")
    tracking, _ = track_source(path, config, seconds=args.seconds)
    return drawn, f"{path} frame {args.frame}", tracking


def _from_device(device: str, args: argparse.Namespace, config: CameraConfig) -> tuple[np.ndarray, str, Tracking]:
    """A live camera's first frame once exposure settled, and the tracking of its first ``--seconds``."""
    from drivers.camera import open_camera
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


def _motion(tracking: Tracking, config: CameraConfig) -> Motion | None:
    """How far the target went in the tracked frames (``quality.motion``): the edge's and a single blob's
    image position (px), a two-point target's body-vector angle (rad); None with fewer than 5 positions."""
    import numpy as np

    from measurement.vision.quality import STILL_PX, motion

    t = np.asarray(tracking.t, dtype=float)
    if t.size < 5:
        return None
    if config.edge:
        return motion(t, np.asarray(tracking.x, dtype=float) * config.camera.fx, STILL_PX)
    b = np.asarray(tracking.b, dtype=float)
    if tracking.a[0] is not None:
        a = np.asarray(tracking.a, dtype=float)
        return motion(t, np.unwrap(np.arctan2(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])))
    across, down = motion(t, b[:, 0], STILL_PX), motion(t, b[:, 1], STILL_PX)
    return across if across.moves or across.span >= down.span else down


def _moving(tracking: Tracking, config: CameraConfig, seconds: float) -> tuple[dict, str]:
    """Whether the target found is one that swings: (facts, refusal or ''). A colour or an edge that matched
    a wall, a ceiling or a table is found in every frame and never moves; only the swinging body is wanted."""
    moved = _motion(tracking, config)
    if moved is None:
        if tracking.frames and tracking.repeated >= tracking.frames // 2:
            return {"moves": False}, (f"the target does not move in the first {seconds:g} s: {tracking.repeated} of "
                                      f"{tracking.frames} frames repeat the previous picture")
        return {}, ""
    unit = "px" if config.edge or tracking.a[0] is None else "rad"
    jitter = f"{moved.jitter:.2g}" if math.isfinite(moved.jitter) else "n/a"
    facts = {"moves": moved.moves, "motion": {"span": float(f"{moved.span:.4g}"), "unit": unit,
                                              "jitter": float(f"{moved.jitter:.3g}") if math.isfinite(moved.jitter) else None}}
    if moved.moves:
        return facts, ""
    what = "its position" if unit == "px" else "its angle"
    return facts, (f"the target does not move in the first {seconds:g} s ({what} spans {moved.span:.2g} {unit}, "
                   f"jitter {jitter} {unit}): it is not the swinging body (something else of its colour or "
                   "contrast? set [target] roi or the colour) or the swing starts later (--seconds)")


def run(args: argparse.Namespace) -> int:
    import cv2

    config = read_camera(args.camera) if args.camera else demo_camera()
    img, where, tracking = _grab(args, config)
    facts: dict = {}
    extra: list[str] = []
    refusal = ""
    if tracking is not None:
        facts, extra, refusal = _share(tracking, config, args.seconds)
        motion_facts, still = _moving(tracking, config, args.seconds)
        facts.update(motion_facts)
        if still:
            extra.append("target does NOT move: not the swinging body?")
        # a single blob's angle needs the arc's centre: a track with no arc is refused by identify too
        no_arc = f"the target's track is not a swing's arc ({facts['pivot_note']})" if "pivot_note" in facts else ""
        refusal = refusal or still or no_arc
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
