"""The [target] table, the tracking-quality rules and small marker swings: cheap unit tests."""

from __future__ import annotations

import math

import numpy as np
import pytest

from measurement.errors import VisionError
from measurement.vision.config import CameraConfig
from measurement.vision.marker_pair import MarkerTrack, view_trace
from measurement.vision.quality import MIN_SHARE, assess

CAMERA = {"width": 320, "height": 240, "fps": 30.0}


def config(**target) -> CameraConfig:
    return CameraConfig.from_dict({"camera": CAMERA, "target": target})


def test_a_target_needs_no_calibration_and_the_edge_still_does():
    c = config(kind="tag", roi=[10, 20, 300, 200], id=3, dictionary="apriltag_36h11")
    assert c.target.kind == "tag" and c.target.view == "face-on" and c.target.roi == (10, 20, 300, 200)
    assert c.marker is None and c.camera.cx == pytest.approx(159.5)
    assert CameraConfig.from_dict(c.to_dict()).target == c.target  # round trip
    with pytest.raises(VisionError, match="missing fx"):
        CameraConfig.from_dict({"camera": CAMERA})


@pytest.mark.parametrize(("target", "words"), [
    ({"kind": "dot"}, "kind must be one of"),
    ({"kind": "tag", "view": "side"}, "does not go with kind"),
    ({"kind": "blob", "roi": [0, 0, 400, 100]}, "roi"),
    ({"kind": "tag", "dictionary": "5X5_7"}, "dictionary"),
    ({"kind": "blob", "colour": [300, 0, 0]}, "colour"),
    ({"kind": "blob", "polarity": "grey"}, "polarity"),
    ({"kind": "blob", "pivot": [1]}, "pivot"),
    ({"kind": "tag", "size": 3}, "unknown key"),
])
def test_target_table_errors_name_the_key(target, words):
    with pytest.raises(VisionError, match=words):
        config(**target)


def swing(n: int = 300, fps: float = 30.0, amplitude: float = 0.2, noise: float = 1e-4, seed: int = 0):
    t = np.arange(n) / fps
    rng = np.random.default_rng(seed)
    return t, amplitude * np.exp(-0.05 * t) * np.cos(5.4 * t) + noise * rng.standard_normal(n)


def test_a_sparse_track_is_refused_with_its_share_and_longest_gap():
    t, theta = swing()
    keep = (t < 1.0) | (t > 4.0)
    with pytest.raises(VisionError, match=r"tracked in \d+ % of 300 decoded frames, longest gap 3\.1"):
        assess(t, t[keep & (np.arange(t.size) % 2 == 0)], theta[keep & (np.arange(t.size) % 2 == 0)])
    mask, q = assess(t, t[t > 1.5], theta[t > 1.5])
    assert q.share == pytest.approx(1 - 45 / 300, abs=0.01) and q.share >= MIN_SHARE and mask.all()
    assert q.longest_gap_s == pytest.approx(1.5, abs=0.04)


def test_jumps_are_dropped_counted_and_too_many_refused_even_across_missing_frames():
    t, theta = swing()
    drop = np.ones(t.size, dtype=bool)
    drop[50:53] = drop[120] = drop[200:204] = False  # missing frames: uneven times, no jumps
    t_k, th_k = t[drop], theta[drop].copy()
    th_k[[30, 150]] += 0.08  # two frames where the tracker held something else
    mask, q = assess(t, t_k, th_k)
    assert q.jumps == 2 and not mask[30] and not mask[150] and mask.sum() == t_k.size - 2
    assert q.jitter_rad == pytest.approx(1e-4, rel=0.3)
    th_k[::20] += 0.08  # 5 % of the frames
    with pytest.raises(VisionError, match="jumps in"):
        assess(t, t_k, th_k)


def test_a_target_that_does_not_move_is_refused():
    t, _ = swing()
    still = 1e-5 * np.random.default_rng(1).standard_normal(t.size)
    with pytest.raises(VisionError, match="does not move"):
        assess(t, t, still)


def test_a_small_marker_swing_is_taken_as_seen_not_refused():
    t, theta = swing(amplitude=0.03)
    a = np.column_stack([np.full(t.size, 100.0), np.full(t.size, 50.0)])
    b = a + 80 * np.column_stack([np.sin(theta), np.cos(theta)])
    trace = view_trace(MarkerTrack(t=t, a=a, b=b, source="small"))
    assert "view" not in trace.meta and "less than the 0.2 rad" in trace.meta["view_note"]
    assert np.allclose(trace.angle, theta, atol=1e-12)
    # a wide swing still has its view measured and removed (a camera squashing the swing plane by 10 %)
    t, theta = swing(amplitude=0.8)
    b = a + 80 * np.column_stack([0.9 * np.sin(theta), np.cos(theta)])
    wide = view_trace(MarkerTrack(t=t, a=a, b=b, source="wide"))
    assert wide.meta["view"]["axis_ratio"] == pytest.approx(0.9, abs=0.01)
    assert np.max(np.abs(wide.angle - theta)) < math.radians(0.05)


def test_a_shrunk_patch_warp_maps_the_same_pixels_as_the_full_one():
    from measurement.vision.locators import _from_level, _to_level

    a = 0.3
    warp = np.array([[math.cos(a), -math.sin(a), 12.5], [math.sin(a), math.cos(a), -7.25]], dtype=np.float32)
    for s in (1, 2, 3):
        level = _to_level(warp, s)
        c = (s - 1) / 2
        for x_l in ([0.0, 0.0], [5.0, 9.0]):
            full = warp @ np.array([s * x_l[0] + c, s * x_l[1] + c, 1.0])  # the level pixel's centre, full px
            assert s * (level @ np.array([*x_l, 1.0])) + c == pytest.approx(full, abs=1e-4)
        np.testing.assert_allclose(_from_level(level, s), warp, atol=1e-5)


def test_a_large_patch_is_aligned_shrunk_and_follows_the_angle():
    import cv2

    from measurement.vision.locators import MAX_PATCH_PIXELS, make_locator
    from measurement.vision.render import Imaging
    from measurement.vision.render_plane import PlaneRenderer, PlaneScene
    from measurement.vision.target import TargetSpec

    spec = TargetSpec(kind="patch", view="along-axis", roi=(200, 120, 440, 360))  # 240 px square, on the plate
    assert MAX_PATCH_PIXELS < 240 * 240
    r = PlaneRenderer(640, 480, spec, PlaneScene.for_view(640, 480, spec), imaging=Imaging(blur=1.0, noise=2.0),
                      seed=3)
    truth = 0.2 * np.cos(5.4 * np.arange(40) / 60.0)
    loc = make_locator(spec, 640, 480)
    seen = []
    for theta in truth:
        obs = loc.locate(cv2.cvtColor(r.render(float(theta)), cv2.COLOR_BGR2GRAY))
        assert obs.found and obs.a is not None and obs.b is not None
        seen.append(math.atan2(obs.b[0] - obs.a[0], obs.b[1] - obs.a[1]))
    assert loc._scale == 2  # type: ignore[attr-defined]
    turn = np.unwrap(seen) - seen[0]
    sign = np.sign(np.dot(turn, truth - truth[0]))  # the image's angle may turn the other way than θ
    assert np.degrees(np.max(np.abs(sign * turn - (truth - truth[0])))) < 0.02
