"""What docs/vision.md tells a new user, held true: which two spots ``blobs`` takes, what a dark colour matches,
what a guessed pivot does to the angle; and the pictures that show it are drawn by tools/vision_doc_pictures.py."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from measurement.vision.body import provisional_angle
from measurement.vision.locators import BlobLocator, PointObservation
from measurement.vision.target import TargetSpec

ROOT = Path(__file__).resolve().parents[2]
RED = (200, 30, 40)


def scene(spots: list[tuple[int, int, int]]) -> np.ndarray:
    img = np.full((300, 400, 3), (205, 200, 195), np.uint8)
    for u, v, r in spots:
        cv2.circle(img, (u, v), r, RED[::-1], -1)
    return img


def test_blobs_takes_the_two_largest_then_follows_them_in_their_windows():
    loc = BlobLocator(TargetSpec(kind="blobs", colour=RED), 400, 300, count=2)
    first = loc.locate(scene([(250, 130, 12), (150, 120, 14), (60, 250, 8), (330, 40, 6)]))
    assert first.a == pytest.approx((150, 120), abs=0.5) and first.b == pytest.approx((250, 130), abs=0.5)
    # a larger spot appears away from the pair: the pair is still the one followed
    later = loc.locate(scene([(156, 124, 14), (254, 138, 12), (60, 250, 8), (200, 240, 22)]))
    assert later.a == pytest.approx((156, 124), abs=0.5) and later.b == pytest.approx((254, 138), abs=0.5)
    # lost (one spot gone), the region is searched again: the two largest now include the newcomer
    again = loc.locate(scene([(156, 124, 14), (60, 250, 8), (200, 240, 22)]))
    assert again.a is not None and again.b is not None
    assert sorted([again.a, again.b]) == [pytest.approx((156, 124), abs=0.5), pytest.approx((200, 240), abs=0.5)]


def test_a_dark_colour_matches_every_grey_up_to_l_82_and_a_saturated_one_none():
    ramp = np.repeat(np.linspace(0, 255, 256).astype(np.uint8)[None, :, None], 3, axis=2)
    lightness = cv2.cvtColor(ramp.astype(np.float32) / 255, cv2.COLOR_BGR2Lab)[0, :, 0]
    dark = BlobLocator(TargetSpec(kind="blob", colour=(30, 60, 40)), 256, 1).mask(ramp, (0, 0, 256, 1))[0] > 0
    red = BlobLocator(TargetSpec(kind="blob", colour=RED), 256, 1).mask(ramp, (0, 0, 256, 1))[0] > 0
    assert not red.any()
    assert dark[lightness <= 81.5].all() and not dark[lightness >= 83].any()


@pytest.mark.parametrize(("du", "dv", "scale"), [(0.0, -0.05, 1 / 1.05), (0.0, 0.05, 1 / 0.95)])
def test_a_pivot_off_along_the_rod_scales_the_angle(du, dv, scale):
    """Pivot → bob 1 (any unit); a pivot guessed ε too high (dv < 0, image v down) reads angles about 1/(1 + ε)
    as large, too low 1/(1 − ε): the 1 ∓ ε of the docs to first order (within 0.1 % up to 0.3 rad)."""
    for theta in (0.1, 0.3):
        bob = PointObservation(True, b=(math.sin(theta), math.cos(theta)))
        seen = provisional_angle(bob, (du, dv))
        assert seen / theta == pytest.approx(scale, rel=1e-3)


def test_the_pictures_are_drawn_and_linked(tmp_path):
    spec = importlib.util.spec_from_file_location("vision_doc_pictures", ROOT / "tools" / "vision_doc_pictures.py")
    assert spec is not None and spec.loader is not None
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    tool.main([str(tmp_path)])
    doc = (ROOT / "docs" / "vision.md").read_text(encoding="utf-8")
    for name in ("vision-blobs-choice.png", "vision-colour-tolerance.png", "vision-pivot-error.png"):
        drawn = cv2.imread(str(tmp_path / name))
        assert drawn is not None and drawn.shape[0] > 150 and drawn.shape[1] > 400
        assert f"](img/{name})" in doc and (ROOT / "docs" / "img" / name).exists()
