"""Synthetic frames of a body turning in the image plane: the truth for the tag, blob, two-blob and patch
targets (face-on pendulum or a platform seen along its axis) and the mock camera's picture of them.

The body is drawn once, at rest, on its own layer (a rod from the pivot, and
at ``radius`` px from the pivot the target: a printed ArUco tag, a coloured
bob, two blobs, or a textured plate); a frame turns that layer about the
pivot by the swing angle (``cv2.warpAffine``, bilinear: sub-pixel positions
are rendered as partial pixels) and lays it over a textured background that
may hold a static distractor (a dark vertical stripe) and black letterbox
bars. Then Gaussian blur, sensor noise and 8-bit rounding. Angles are
positive towards +u at the bottom (counter-clockwise on screen), the angle
of the vector pivot → target measured from straight down, as the tracker reports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .render import Imaging
from .target import TargetSpec, dictionary_name


@dataclass(frozen=True)
class PlaneScene:
    """The scene: pivot (u, v) px; radius: pivot to the target's centre, px; size: the target's size, px
    (tag side, bob diameter, plate side); letterbox: black bars at the left and right, px; distractor: the
    column (px) of a static dark stripe behind the body (None: none); colour: the bob's R, G, B."""

    pivot: tuple[float, float] = (320.0, 40.0)
    radius: float = 300.0
    size: float = 60.0
    letterbox: int = 0
    distractor: float | None = None
    colour: tuple[int, int, int] = (200, 30, 40)
    tag_id: int = 0

    @classmethod
    def for_view(cls, width: int, height: int, spec: TargetSpec) -> "PlaneScene":
        """A scene that fills a width × height frame: a pendulum hanging from near the top (face-on) or a
        platform turning about the centre (along the axis)."""
        colour = tuple(int(c) for c in spec.colour) if spec.colour is not None else (200, 30, 40)
        if spec.view == "along-axis" or spec.kind in ("blobs", "patch"):
            return cls(pivot=((width - 1) / 2, (height - 1) / 2), radius=0.3 * height, size=0.08 * height,
                       colour=colour)  # type: ignore[arg-type]
        # a tag a quarter of the frame high: 60 px or more across, as docs/vision.md asks of a printed tag
        size = (0.25 if spec.kind == "tag" else 0.13) * height
        return cls(pivot=((width - 1) / 2, 0.05 * height), radius=0.62 * height, size=size,
                   colour=colour)  # type: ignore[arg-type]


class PlaneRenderer:
    """Renders BGR uint8 frames of ``spec.kind`` (tag, blob, blobs, patch) at swing angle θ (rad)."""

    def __init__(self, width: int, height: int, spec: TargetSpec, scene: PlaneScene = PlaneScene(),
                 imaging: Imaging = Imaging(blur=0.8, noise=2.0), seed: int = 0):
        self.width, self.height, self.spec, self.scene, self.imaging = width, height, spec, scene, imaging
        self._rng = np.random.default_rng(seed)
        self._background = self._draw_background()
        self._layer, self._alpha = self._draw_body()

    def _draw_background(self) -> np.ndarray:
        rng = np.random.default_rng(12345)
        # a smooth, faintly textured wall: low-frequency shading plus fine grain
        low = cv2.resize(rng.uniform(150, 200, (6, 8)).astype(np.float32), (self.width, self.height),
                         interpolation=cv2.INTER_CUBIC)
        img = np.repeat(low[:, :, None], 3, axis=2) * np.array([0.95, 1.0, 1.03], np.float32)
        s = self.scene
        if s.distractor is not None:
            c = int(round(s.distractor))
            img[:, max(c - 6, 0):c + 6] = 30.0
        return img

    def _draw_body(self) -> tuple[np.ndarray, np.ndarray]:
        s = self.scene
        layer = np.zeros((self.height, self.width, 3), np.float32)
        alpha = np.zeros((self.height, self.width), np.float32)
        pu, pv = s.pivot
        cu, cv_ = pu, pv + s.radius  # the target's centre at rest, straight below the pivot
        half = s.size / 2
        kind = self.spec.kind

        def paint(mask: np.ndarray, colour: tuple[float, float, float]) -> None:
            layer[mask > 0] = colour
            alpha[mask > 0] = 1.0

        rod = np.zeros((self.height, self.width), np.uint8)
        if kind in ("tag", "blob"):
            cv2.line(rod, (int(pu), int(pv)), (int(cu), int(cv_ - half)), 255, 3)
            paint(rod, (90, 90, 90))
        if kind == "tag":
            side = int(round(s.size))
            name = dictionary_name(self.spec.dictionary) or "DICT_4X4_50"
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
            tag = cv2.aruco.generateImageMarker(dictionary, self.spec.tag_id or s.tag_id, side, borderBits=1)
            quiet = side // 5
            board = cv2.copyMakeBorder(tag, quiet, quiet, quiet, quiet, cv2.BORDER_CONSTANT, value=255)
            n = board.shape[0]
            # the tag laid on with sub-pixel placement (a translation warp of the printed board)
            m = np.array([[1, 0, cu - (n - 1) / 2], [0, 1, cv_ - (n - 1) / 2]], dtype=np.float32)
            placed = cv2.warpAffine(board.astype(np.float32), m, (self.width, self.height), flags=cv2.INTER_LINEAR)
            cover = cv2.warpAffine(np.ones_like(board, np.float32), m, (self.width, self.height), flags=cv2.INTER_LINEAR)
            layer[:] = layer * (1 - cover[..., None]) + placed[..., None] * cover[..., None]
            alpha[:] = np.maximum(alpha, cover)
        elif kind == "blob":
            r, g, b = s.colour
            self._disc(layer, alpha, (cu, cv_), half, (b, g, r))
        elif kind == "blobs":
            # two dark discs on a light plate turning about the pivot (a platform seen from above)
            self._disc(layer, alpha, (pu, pv), s.radius + s.size, (215, 215, 215))
            for sign in (-1, 1):
                self._disc(layer, alpha, (pu + sign * 0.6 * s.radius, pv + 0.5 * s.radius), half, (25, 25, 25))
        elif kind == "patch":
            self._disc(layer, alpha, (pu, pv), s.radius + s.size, (170, 170, 170))
            rng = np.random.default_rng(7)
            tex = cv2.GaussianBlur(rng.uniform(40, 230, (self.height, self.width)).astype(np.float32), (0, 0), 2.5)
            plate = np.zeros((self.height, self.width), np.uint8)
            cv2.circle(plate, (int(pu), int(pv)), int(s.radius), 255, -1)
            layer[plate > 0] = tex[plate > 0, None]
        return layer, alpha

    @staticmethod
    def _disc(layer: np.ndarray, alpha: np.ndarray, centre: tuple[float, float], radius: float,
              bgr: tuple[float, float, float]) -> None:
        """An anti-aliased disc (coverage from the distance to its rim)."""
        h, w = alpha.shape
        v, u = np.mgrid[0:h, 0:w].astype(np.float32)
        cover = np.clip(radius + 0.5 - np.hypot(u - centre[0], v - centre[1]), 0.0, 1.0)
        layer[:] = layer * (1 - cover[..., None]) + np.asarray(bgr, np.float32) * cover[..., None]
        np.maximum(alpha, cover, out=alpha)

    def target_points(self, theta: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """Where the pivot and the target's centre are at θ (rad), px (the truth for the tests)."""
        pu, pv = self.scene.pivot
        r = self.scene.radius
        return (pu, pv), (pu + r * math.sin(theta), pv + r * math.cos(theta))

    def render_at(self, angle_of_time, t: float) -> np.ndarray:
        """The frame at time t (s) from an angle source θ(t) (rad): BGR for a colour target, else grey (what
        the camera delivers for it)."""
        img = self.render(float(angle_of_time(t)))
        return img if self.spec.needs_colour else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)

    def render(self, theta: float, occlude: bool = False) -> np.ndarray:
        """One BGR frame with the body turned by θ (rad); occlude: a grey card hides the target."""
        pu, pv = self.scene.pivot
        # OpenCV's positive angle turns the picture counter-clockwise on screen: the bottom towards +u
        m = cv2.getRotationMatrix2D((pu, pv), math.degrees(theta), 1.0)
        layer = cv2.warpAffine(self._layer, m, (self.width, self.height), flags=cv2.INTER_LINEAR)
        alpha = cv2.warpAffine(self._alpha, m, (self.width, self.height), flags=cv2.INTER_LINEAR)[..., None]
        img = self._background * (1 - alpha) + layer * alpha
        if occlude:
            (_, _), (tu, tv) = self.target_points(theta)
            h = self.scene.size * 1.5 + (self.scene.radius if self.spec.kind in ("blobs", "patch") else 0)
            img[max(int(tv - h), 0):int(tv + h), max(int(tu - h), 0):int(tu + h)] = 120.0
        if self.imaging.blur > 0:
            img = cv2.GaussianBlur(img, (0, 0), self.imaging.blur)
        if self.imaging.noise > 0:
            img = img + self.imaging.noise * self._rng.standard_normal(img.shape, dtype=np.float32)
        lb = self.scene.letterbox
        if lb:
            img[:, :lb] = 0
            img[:, self.width - lb:] = 0
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)
