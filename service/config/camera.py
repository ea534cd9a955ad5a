"""Reading the camera file (TOML: [camera], [marker], optional [pose]; see docs/vision.md) with errors that
name the file and the key."""

from __future__ import annotations

import os

from measurement.errors import VisionError
from measurement.vision.config import CameraConfig
from service.sources.files import read_toml_as


def read_camera(path: str | os.PathLike) -> CameraConfig:
    """The camera file at ``path``: intrinsics, distortion, marker radius and distance (and optional [pose])."""
    return read_toml_as(path, "camera file", CameraConfig.from_dict, VisionError)


def camera_config(camera: str | os.PathLike | CameraConfig) -> CameraConfig:
    """A camera file path or an already parsed ``CameraConfig``."""
    return camera if isinstance(camera, CameraConfig) else read_camera(camera)
