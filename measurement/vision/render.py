"""Synthetic camera frames of the marker: the truth for the vision tests and the mock camera.

The scene is ray-traced, independently of the extraction code: every pixel's
ray (through the lens distortion and the camera's yaw/pitch/roll) is
intersected with the vertical cylinder that carries the marker, by solving
the ray–circle quadratic, and coloured by where it lands on the cylinder.
The marker is a dark field and a bright field that meet at a vertical edge
(the line the tracker measures); around it the cylinder is mid-grey, and
beyond the cylinder's silhouette is the background.

Imaging effects: pixel area integration (the edge covers a pixel partially),
motion blur over the exposure, Gaussian optical blur (σ in px), additive
Gaussian sensor noise (σ in grey levels) and 8-bit quantisation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from ..errors import VisionError
from .config import CameraModel, MarkerGeometry
from .geometry import axis_distance


@dataclass(frozen=True)
class MarkerPattern:
    """The printed marker and the lighting, as grey levels (0–255).

    half_width: arc length of each field (dark and bright) on the cylinder, m.
    height: vertical size of the marker, m. centre_height: its centre below
    the camera's optical centre, m (image v grows downwards).
    """

    half_width: float = 0.02
    height: float = 0.06
    centre_height: float = 0.0
    dark: float = 25.0
    bright: float = 225.0
    surface: float = 128.0
    background: float = 60.0


@dataclass(frozen=True)
class CameraPose:
    """How the camera is set up relative to the ideal (axis through the marker and the swing axis).

    yaw: ψ, rad, optical axis turned towards +u about the vertical.
    pitch: rad, optical axis turned downwards. roll: rad, about the optical axis.
    rest_angle: φ0, rad, the marker's surface angle at rest, seen from the
    camera (a camera moved sideways and re-aimed at the marker has φ0 ≠ 0).
    """

    yaw: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    rest_angle: float = 0.0


@dataclass(frozen=True)
class Imaging:
    """Image degradations.

    blur: σ of the Gaussian optical blur, px. noise: σ of additive sensor noise, grey levels.
    exposure: s, the shutter is open this long centred on the frame time (motion blur).
    """

    blur: float = 1.0
    noise: float = 2.0
    exposure: float = 0.0


def _rotation(pose: CameraPose) -> np.ndarray:
    """Camera → world rotation. World: X right, Y down, Z horizontal towards the swing axis."""
    cy, sy = math.cos(pose.yaw), math.sin(pose.yaw)
    cp, sp = math.cos(pose.pitch), math.sin(pose.pitch)
    cr, sr = math.cos(pose.roll), math.sin(pose.roll)
    yaw = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    pitch = np.array([[1.0, 0.0, 0.0], [0.0, cp, sp], [0.0, -sp, cp]])
    roll = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    return yaw @ pitch @ roll


def _ramp(q: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Share of a pixel where q > 0, when q changes by ``width`` across the pixel (box integration)."""
    return np.clip(q / width + 0.5, 0.0, 1.0)


class MarkerRenderer:
    """Renders 8-bit grey frames of the marker at a given swing angle.

    camera: intrinsics and image size; marker: R and D; pattern, pose,
    imaging: see their classes. seed: the sensor noise is reproducible.
    """

    def __init__(self, camera: CameraModel, marker: MarkerGeometry, *, pattern: MarkerPattern = MarkerPattern(),
                 pose: CameraPose = CameraPose(), imaging: Imaging = Imaging(), seed: int | None = None):
        if imaging.blur < 0 or imaging.noise < 0 or imaging.exposure < 0:
            raise VisionError("blur, noise and exposure must be >= 0")
        self.camera, self.marker, self.pattern, self.pose, self.imaging = camera, marker, pattern, pose, imaging
        self._rng = np.random.default_rng(seed)
        H, W = camera.height, camera.width
        R = marker.radius
        L = axis_distance(marker, pose.rest_angle)
        self.axis_distance = L
        v, u = np.mgrid[0:H, 0:W].astype(float)
        x, y = camera.undistort(u, v)
        d = np.stack([x, y, np.ones_like(x)], axis=-1) @ _rotation(pose).T
        dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
        h = np.hypot(dx, dz)
        sx, sz = dx / h, dz / h
        disc = R * R - (L * sx) ** 2
        hit = (disc >= 0) & (sz > 0)
        s = np.where(hit, L * sz - np.sqrt(np.where(hit, disc, 0.0)), np.nan)  # nearer root: the front of the cylinder
        px, pz = s * sx, s * sz
        self._phi = np.arctan2(px, L - pz)  # surface angle, rad
        self._height = s / h * dy  # vertical position on the cylinder, m (down positive)
        self._hit = hit
        # Per-pixel change of the surface coordinates, for area integration of the edges.
        self._dphi = np.abs(np.gradient(np.where(hit, self._phi, np.nan), axis=1)) + np.abs(np.gradient(
            np.where(hit, self._phi, np.nan), axis=0))
        self._dh = np.abs(np.gradient(self._height, axis=0)) + np.abs(np.gradient(self._height, axis=1))
        # Off the cylinder (and on its silhouette) the derivatives are undefined; those pixels are
        # background, so any finite footprint will do.
        for name in ("_dphi", "_dh"):
            arr = getattr(self, name)
            good = np.isfinite(arr) & (arr > 0)
            setattr(self, name, np.where(good, arr, np.median(arr[good]) if good.any() else 1.0))
        self._rel_far = 10.0  # rad: "far from the edge" for pixels off the cylinder
        # Rows that can show the marker (with room for the blur kernel): only these change per frame.
        p = pattern
        near = hit & (np.abs(np.where(hit, self._height, np.inf) - p.centre_height) <= p.height / 2 + 2 * self._dh)
        rows = np.flatnonzero(near.any(axis=1))
        margin = int(math.ceil(4 * imaging.blur)) + 2
        self._r0 = max(int(rows.min()) - margin, 0) if rows.size else 0
        self._r1 = min(int(rows.max()) + margin + 1, H) if rows.size else 0
        static = np.where(hit, p.surface, p.background).astype(np.float32)
        self._static = static
        self._static_blurred = self._blur(static)

    def _blur(self, img: np.ndarray) -> np.ndarray:
        if self.imaging.blur <= 0:
            return img
        return cv2.GaussianBlur(img, (0, 0), self.imaging.blur, borderType=cv2.BORDER_REFLECT)

    def _band(self, phi_edge: float) -> np.ndarray:
        """Sharp (area-integrated) grey levels of the marker band for the edge at surface angle phi_edge."""
        p = self.pattern
        sl = slice(self._r0, self._r1)
        phi, hh, hit = self._phi[sl], self._height[sl], self._hit[sl]
        dphi, dh = self._dphi[sl], self._dh[sl]
        rel = np.where(hit, phi - phi_edge, self._rel_far)
        half = p.half_width / self.marker.radius
        bright_share = _ramp(rel, dphi)
        inside = _ramp(half - np.abs(rel), dphi) * _ramp(p.height / 2 - np.abs(hh - p.centre_height), dh)
        inside = np.where(hit, inside, 0.0)
        marker = p.dark + (p.bright - p.dark) * bright_share
        return np.where(hit, p.surface + inside * (marker - p.surface), p.background)

    def render(self, theta: float | Sequence[float]) -> np.ndarray:
        """One frame, uint8 H×W, with the marker at swing angle θ (rad).

        A sequence of angles is averaged before blur and noise: the motion
        blur of angles sampled evenly over the exposure.
        """
        thetas = np.atleast_1d(np.asarray(theta, dtype=float))
        if not np.isfinite(thetas).all():
            raise VisionError(f"cannot render a non-finite angle {theta!r}")
        band = np.zeros((self._r1 - self._r0, self.camera.width))
        for th in thetas:
            band += self._band(th + self.pose.rest_angle)
        band /= thetas.size
        img = self._static_blurred.astype(np.float32)  # a copy; float32 halves the cost of a frame
        if self._r1 > self._r0:
            sharp = self._static.copy()
            sharp[self._r0:self._r1] = band
            blurred_band = self._blur(sharp[max(self._r0 - 8, 0):self._r1 + 8])
            off = self._r0 - max(self._r0 - 8, 0)
            img[self._r0:self._r1] = blurred_band[off:off + self._r1 - self._r0]
        if self.imaging.noise > 0:
            noise = self._rng.standard_normal(img.shape, dtype=np.float32)
            noise *= self.imaging.noise
            img += noise
        np.rint(img, out=img)
        np.clip(img, 0, 255, out=img)
        return img.astype(np.uint8)

    def render_at(self, angle_of_time, t: float) -> np.ndarray:
        """Frame at time t (s) from an angle source θ(t) (rad), with the motion blur of the exposure."""
        exp = self.imaging.exposure
        if exp > 0:
            n = 5
            times = t + exp * (np.arange(n) + 0.5 - n / 2) / n
            return self.render([float(angle_of_time(tt)) for tt in times])
        return self.render(float(angle_of_time(t)))
