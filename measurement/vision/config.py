"""The camera file (TOML), parsed and checked (no file I/O here).

```toml
[camera]
width = 640            # px
height = 480           # px
fps = 60.0             # frames/s: a live camera's, an image folder's; a video's container has its own
fx = 600.0             # focal length, px
fy = 600.0
cx = 319.5             # principal point, px (pixel centres are integers)
cy = 239.5
distortion = [0.0, 0.0, 0.0, 0.0, 0.0]   # OpenCV k1 k2 p1 p2 k3
[marker]
radius = 0.10          # m, swing axis to the marker surface
distance = 0.25        # m, camera (optical centre) to the marker at rest
[pose]                 # optional
yaw_limit_deg = 2.0    # flag camera_pose above this |yaw|, degrees
estimate = true        # estimate the yaw from the swing and correct the angle
[target]               # optional: what is tracked and how the camera looks (measurement.vision.target)
kind = "tag"           # tag | blob | blobs | patch | edge (default edge, which needs [marker])
```

Only the edge on a cylinder needs the calibration (fx … distortion) and
``[marker]``; the other targets are measured in the image plane, where the
image size is all that is needed (fx … default to a centred, undistorted
camera). The frame rate is needed where the frames have no times of their
own: a live or simulated camera, an image folder without timestamps; a
video's times come from its container.

Every error says which key is wrong and what was expected; they are
``VisionError`` (an ``InvalidInput``: one line on stderr, exit status 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal, Mapping, overload

import numpy as np

from ..errors import VisionError
from .target import TargetSpec

_CAMERA_KEYS = ("width", "height", "fps", "fx", "fy", "cx", "cy", "distortion")
_MARKER_KEYS = ("radius", "distance")
_POSE_KEYS = ("yaw_limit_deg", "estimate")

#: default |yaw| above which a measurement is flagged ``camera_pose``, degrees
DEFAULT_YAW_LIMIT_DEG = 2.0


def _number(table: str, key: str, value: Any, unit: str, *, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise VisionError(f"camera file: [{table}] {key} must be a number in {unit}, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise VisionError(f"camera file: [{table}] {key} must be finite ({unit}), got {value!r}")
    if positive and v <= 0:
        raise VisionError(f"camera file: [{table}] {key} must be > 0 {unit}, got {value!r}")
    return v


def _integer(table: str, key: str, value: Any, unit: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise VisionError(f"camera file: [{table}] {key} must be a whole number > 0 {unit}, got {value!r}")
    return int(value)


@overload
def _table(doc: Mapping[str, Any], name: str, keys: tuple[str, ...], required: Literal[True]) -> Mapping[str, Any]: ...
@overload
def _table(doc: Mapping[str, Any], name: str, keys: tuple[str, ...],
           required: Literal[False]) -> Mapping[str, Any] | None: ...
def _table(doc: Mapping[str, Any], name: str, keys: tuple[str, ...], required: bool) -> Mapping[str, Any] | None:
    """The table ``name`` of ``doc``, checked for unknown (and, if required, missing) keys; None when an
    optional table is absent (a required one raises VisionError)."""
    t = doc.get(name)
    if t is None:
        if required:
            raise VisionError(f"camera file: missing [{name}] table; expected keys {', '.join(keys)}")
        return None
    if not isinstance(t, Mapping):
        raise VisionError(f"camera file: {name} must be a table [{name}], got {type(t).__name__}")
    unknown = sorted(set(t) - set(keys))
    if unknown:
        raise VisionError(f"camera file: unknown key(s) in [{name}]: {unknown}; expected {', '.join(keys)}")
    if required:
        missing = [k for k in keys if k not in t]
        if missing:
            raise VisionError(f"camera file: [{name}] is missing {', '.join(missing)}")
    return t


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics with OpenCV's lens distortion.

    width, height: image size, px. fps: nominal frame rate, frames/s (None: not given; a video's container
    has its own, a live camera needs it: ``frame_rate``).
    fx, fy: focal lengths, px. cx, cy: principal point, px (the centre of
    pixel (i, j) is at u = j, v = i, OpenCV's convention).
    distortion: (k1, k2, p1, p2, k3), OpenCV's radial/tangential model.
    """

    width: int
    height: int
    fps: float | None
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def frame_rate(self, needed_by: str) -> float:
        """The frame rate (frames/s), which ``needed_by`` cannot do without; VisionError when not given."""
        if self.fps is None:
            raise VisionError(f"camera file: [camera] fps is missing; {needed_by} needs the frame rate (frames/s)")
        return self.fps

    @property
    def matrix(self) -> np.ndarray:
        """3×3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        return np.asarray(self.distortion, dtype=float)

    @property
    def distorted(self) -> bool:
        return any(d != 0.0 for d in self.distortion)

    def undistort(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw pixel coordinates (px) → ideal normalised image coordinates x/z, y/z (dimensionless)."""
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        if not self.distorted:
            return (u - self.cx) / self.fx, (v - self.cy) / self.fy
        import cv2

        pts = np.stack([u.ravel(), v.ravel()], axis=-1).reshape(-1, 1, 2)
        # Iterated to convergence: the default 5 iterations leave ~0.01 px at the corners
        # with a strong k1, which is more than the marker's sub-pixel budget.
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)
        out = cv2.undistortPoints(pts, self.matrix, self.dist_coeffs, criteria=crit).reshape(-1, 2)
        return out[:, 0].reshape(u.shape), out[:, 1].reshape(v.shape)

    def distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalised coordinates → raw pixel coordinates, px (OpenCV's forward lens model)."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        k1, k2, p1, p2, k3 = self.distortion
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return self.fx * xd + self.cx, self.fy * yd + self.cy

    def to_dict(self) -> dict[str, Any]:
        rate = {} if self.fps is None else {"fps": self.fps}
        return {"width": self.width, "height": self.height, **rate, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy, "distortion": list(self.distortion)}


@dataclass(frozen=True)
class MarkerGeometry:
    """Where the marker is: on a cylinder about the swing axis, seen from the camera.

    radius: R, m, swing axis to the marker surface.
    distance: D, m, camera optical centre to the marker at rest.
    """

    radius: float
    distance: float

    @property
    def axis_distance(self) -> float:
        """L = D + R, m: camera to swing axis when the marker at rest faces the camera."""
        return self.distance + self.radius

    def to_dict(self) -> dict[str, Any]:
        return {"radius": self.radius, "distance": self.distance}


@dataclass(frozen=True)
class PoseSettings:
    """What to do about a yawed camera.

    yaw_limit_deg: |yaw| above which the result is flagged ``camera_pose``, degrees.
    estimate: estimate the yaw from the swing and correct the angle trace.
    """

    yaw_limit_deg: float = DEFAULT_YAW_LIMIT_DEG
    estimate: bool = True


@dataclass(frozen=True)
class CameraConfig:
    """A parsed camera file: intrinsics, marker geometry and pose settings."""

    camera: CameraModel
    marker: MarkerGeometry | None
    pose: PoseSettings = field(default_factory=PoseSettings)
    target: TargetSpec = field(default_factory=TargetSpec)

    @property
    def edge(self) -> bool:
        """The target is the edge on a cylinder (side view), measured with the calibration and [marker]."""
        return self.target.kind == "edge"

    @property
    def cylinder(self) -> MarkerGeometry:
        """The edge's cylinder ([marker]); only an edge target has one (checked when the file is read)."""
        assert self.marker is not None, "an edge target's camera file has [marker]"
        return self.marker

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> "CameraConfig":
        """Build from the parsed TOML document; raises VisionError naming the bad key."""
        if not isinstance(doc, Mapping):
            raise VisionError("camera file: expected a TOML document with [camera] and [marker] tables")
        unknown = sorted(set(doc) - {"camera", "marker", "pose", "target"})
        if unknown:
            raise VisionError(f"camera file: unknown table(s) {unknown}; expected [camera], optionally [target], "
                              "and [marker] for an edge target, [pose]")
        c = _table(doc, "camera", _CAMERA_KEYS, False)
        if c is None:
            raise VisionError("camera file: missing [camera] table; expected at least width and height")
        for k in ("width", "height"):
            if k not in c:
                raise VisionError(f"camera file: [camera] is missing {k}")
        width = _integer("camera", "width", c["width"], "px")
        height = _integer("camera", "height", c["height"], "px")
        t = doc.get("target", {})
        if not isinstance(t, Mapping):
            raise VisionError(f"camera file: target must be a table [target], got {type(t).__name__}")
        target = TargetSpec.from_dict(t, width, height)
        if target.kind == "edge":
            missing = [k for k in _CAMERA_KEYS if k not in c]
            if missing:
                raise VisionError(f"camera file: [camera] is missing {', '.join(missing)} (the edge on a cylinder is "
                                  "measured with the camera's calibration)")
        m = (_table(doc, "marker", _MARKER_KEYS, True) if target.kind == "edge"
             else _table(doc, "marker", _MARKER_KEYS, False))
        p = _table(doc, "pose", _POSE_KEYS, False)
        cx = _number("camera", "cx", c.get("cx", (width - 1) / 2), "px", positive=False)
        cy = _number("camera", "cy", c.get("cy", (height - 1) / 2), "px", positive=False)
        if not (0 <= cx <= width - 1 and 0 <= cy <= height - 1):
            raise VisionError(f"camera file: [camera] principal point ({cx:g}, {cy:g}) px lies outside the "
                              f"{width}×{height} image; expected 0 ≤ cx ≤ {width - 1}, 0 ≤ cy ≤ {height - 1}")
        dist = c.get("distortion", [0.0] * 5)
        if not isinstance(dist, list) or len(dist) != 5:
            raise VisionError(f"camera file: [camera] distortion must be a list of 5 numbers [k1, k2, p1, p2, k3], got {dist!r}")
        k1, k2, p1, p2, k3 = (_number("camera", f"distortion[{i}]", d, "", positive=False) for i, d in enumerate(dist))
        focal = float(max(width, height))
        camera = CameraModel(
            width=width, height=height, fps=_number("camera", "fps", c["fps"], "frames/s") if "fps" in c else None,
            fx=_number("camera", "fx", c.get("fx", focal), "px"), fy=_number("camera", "fy", c.get("fy", focal), "px"),
            cx=cx, cy=cy, distortion=(k1, k2, p1, p2, k3),
        )
        marker = None
        if m is not None:
            marker = MarkerGeometry(radius=_number("marker", "radius", m["radius"], "m"),
                                    distance=_number("marker", "distance", m["distance"], "m"))
        pose = PoseSettings()
        if p is not None:
            estimate = p.get("estimate", True)
            if not isinstance(estimate, bool):
                raise VisionError(f"camera file: [pose] estimate must be true or false, got {estimate!r}")
            limit = _number("pose", "yaw_limit_deg", p.get("yaw_limit_deg", DEFAULT_YAW_LIMIT_DEG), "degrees")
            pose = PoseSettings(yaw_limit_deg=limit, estimate=estimate)
        return cls(camera=camera, marker=marker, pose=pose, target=target)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"camera": self.camera.to_dict()}
        if self.marker is not None:
            out["marker"] = self.marker.to_dict()
        out["pose"] = {"yaw_limit_deg": self.pose.yaw_limit_deg, "estimate": self.pose.estimate}
        if not self.edge or self.target != TargetSpec():
            out["target"] = self.target.to_dict()
        return out
