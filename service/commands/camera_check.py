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
from service.sources.marker_check import check_image

if TYPE_CHECKING:  # the vision modules load OpenCV: imported where used, not for `moi --help`
    import numpy as np

    from measurement.vision.config import CameraConfig


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
