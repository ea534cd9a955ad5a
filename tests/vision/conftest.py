"""Vision fixtures: the test camera, the torsion swing, and rendered videos shared by the end-to-end tests.

Every frame is rendered here (measurement.vision.render); nothing is read
from outside the repository.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
import tomli_w

from measurement import Pendulum, Rig, Swing
from measurement.vision import CameraConfig, CameraModel, CameraPose, Imaging, MarkerGeometry, MarkerRenderer

# 640×480, fx = 600 px (a 56° horizontal field), marker on a 0.1 m radius, camera 0.25 m away:
# 240 px per rad at rest, so 0.01° is 0.042 px.
FPS = 60.0
CAMERA = CameraModel(width=640, height=480, fps=FPS, fx=600.0, fy=600.0, cx=319.5, cy=239.5)
MARKER = MarkerGeometry(radius=0.10, distance=0.25)
CONFIG = CameraConfig(camera=CAMERA, marker=MARKER)
# the imaging the vision path's accuracy is specified for: a little blur, 2 grey levels of noise
IMAGING = Imaging(blur=1.0, noise=2.0)

RIG = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
J_TRUE = 0.0125
VISCOUS_C = 1.5e-4
THETA0 = 0.2  # rad, 11.5°: where sin θ and tan θ differ by 2 %


def camera_toml(config: CameraConfig = CONFIG, **pose) -> dict:
    doc = {"camera": config.camera.to_dict(), "marker": config.cylinder.to_dict()}
    if pose:
        doc["pose"] = pose
    return doc


def write_toml(path: Path, doc: dict) -> Path:
    path.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return path


def truth_swing(duration: float = 21.0) -> Swing:
    return Swing(Pendulum(RIG, J_TRUE, {"viscous": {"c": VISCOUS_C}}), theta0=THETA0, duration=duration)


def write_video(path: Path, frames, fps: float = 60.0) -> Path:
    """MJPG in AVI (what a V4L2 camera streams), quality 95."""
    w = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (CAMERA.width, CAMERA.height), isColor=False)
    assert w.isOpened()
    w.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
    for f in frames:
        w.write(f)
    w.release()
    return path


@dataclass
class RenderedSwing:
    video: Path
    camera_file: Path
    rig_file: Path
    yaw_deg: float
    swing: Swing


def _render_swing(tmp: Path, yaw_deg: float, duration: float = 20.0, seed: int = 11) -> RenderedSwing:
    swing = truth_swing(duration + 1.0)
    renderer = MarkerRenderer(CAMERA, MARKER, pose=CameraPose(yaw=math.radians(yaw_deg)), imaging=IMAGING, seed=seed)
    t = np.arange(int(round(duration * FPS))) / FPS
    video = write_video(tmp / f"swing_yaw{yaw_deg:g}.avi", (renderer.render(swing.angle(ti)) for ti in t))
    cam = write_toml(tmp / "camera.toml", camera_toml())
    rig = write_toml(tmp / "rig.toml", RIG.to_dict())
    return RenderedSwing(video, cam, rig, yaw_deg, swing)


@pytest.fixture(scope="session")
def swing_video(tmp_path_factory) -> RenderedSwing:
    """A 20 s, 60 frames/s video of the torsion swing, camera straight."""
    return _render_swing(tmp_path_factory.mktemp("video0"), 0.0)


@pytest.fixture(scope="session")
def yawed_swing_video(tmp_path_factory) -> RenderedSwing:
    """The same swing seen by a camera yawed by 4°."""
    return _render_swing(tmp_path_factory.mktemp("video4"), 4.0)
