"""`moi camera-check`: a frame, where the marker is, the angle, and a PNG for the technician."""

import json
import math

import cv2
import numpy as np
import pytest

from measurement.vision import CameraPose, MarkerRenderer
from service.cli import main

from .conftest import CAMERA, IMAGING, MARKER, camera_toml, write_toml, write_video


def test_mock_camera_by_default(tmp_path, capsys):
    out = tmp_path / "check.png"
    assert main(["camera-check", "--angle", "5", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "mock camera" in text and "angle +5.00" in text and str(out) in text
    png = cv2.imread(str(out))
    assert png is not None
    assert png is not None and png.shape == (480, 640, 3)
    # the annotation is drawn in colour over the grey frame
    assert np.any(png[..., 2].astype(int) - png[..., 1].astype(int) > 100)


def test_json_with_a_camera_file_and_a_yawed_view(tmp_path, capsys):
    """A still frame from a camera yawed by 3°: the implied yaw of a marker at rest is printed."""
    img = MarkerRenderer(CAMERA, MARKER, pose=CameraPose(yaw=math.radians(3.0)), imaging=IMAGING, seed=1).render(0.0)
    cv2.imwrite(str(tmp_path / "still.png"), img)
    cam = write_toml(tmp_path / "cam.toml", camera_toml())
    assert main(["camera-check", "--camera", str(cam), "--source", str(tmp_path / "still.png"),
                 "--out", str(tmp_path / "c.png"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["found"] is True
    assert report["implied_yaw_deg_if_at_rest"] == pytest.approx(3.0, abs=0.01)
    assert report["offset_px"] == pytest.approx(-600 * math.tan(math.radians(3.0)), abs=0.05)
    assert abs(report["tilt_deg"]) < 0.05 and report["rows"] > 100


def test_frame_of_a_video(tmp_path, capsys):
    r = MarkerRenderer(CAMERA, MARKER, imaging=IMAGING, seed=2)
    video = write_video(tmp_path / "v.avi", (r.render(a) for a in (0.0, 0.1, 0.2)))
    assert main(["camera-check", "--source", str(video), "--frame", "2", "--out", str(tmp_path / "c.png"),
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["angle_deg"] == pytest.approx(math.degrees(0.2), abs=0.02)
    assert main(["camera-check", "--source", str(video), "--frame", "7", "--out", str(tmp_path / "c.png")]) == 2
    assert "has no frame 7" in capsys.readouterr().err


def test_no_marker_still_writes_the_png_and_exits_2(tmp_path, capsys):
    cv2.imwrite(str(tmp_path / "wall.png"), np.full((480, 640), 120, np.uint8))
    out = tmp_path / "c.png"
    assert main(["camera-check", "--source", str(tmp_path / "wall.png"), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert "NOT found" in captured.out
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "marker not found" in err[0] and str(out) in err[0]
    assert cv2.imread(str(out)) is not None


def test_bad_arguments_are_one_line_errors(tmp_path, capsys):
    assert main(["camera-check", "--source", str(tmp_path / "missing.png")]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["camera-check", "--out", str(tmp_path / "no-dir" / "c.png")]) == 2
    assert "cannot write" in capsys.readouterr().err
    assert main(["camera-check", "--device", "/dev/video-not-here", "--out", str(tmp_path / "c.png")]) == 2
    assert "does not exist" in capsys.readouterr().err


@pytest.mark.parametrize("target", [{"kind": "tag"}, {"kind": "blob", "colour": [200, 30, 40]},
                                    {"kind": "blobs", "view": "along-axis"},
                                    {"kind": "patch", "view": "along-axis", "roi": [110, 70, 210, 170]}])
def test_each_target_rendered_by_the_mock_is_found_and_drawn(tmp_path, capsys, target):
    cam = write_toml(tmp_path / "cam.toml", {"camera": {"width": 320, "height": 240, "fps": 30.0}, "target": target})
    out = tmp_path / "c.png"
    assert main(["camera-check", "--camera", str(cam), "--angle", "8", "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["found"] is True and report["target"] == target["kind"]
    if target["kind"] not in ("blob", "patch"):  # a blob needs its pivot; a patch turns from its first frame
        assert report["angle_deg"] == pytest.approx(8.0 + (90.0 if target["kind"] == "blobs" else 0.0), abs=0.3)
    png = cv2.imread(str(out))
    assert png is not None
    drawn = np.abs(png[..., 1].astype(int) - png[..., 2].astype(int)) > 100  # the green axis or the red target
    assert png.shape == (240, 320, 3) and drawn.any()


def test_a_video_positional_reports_the_share_and_refuses_like_identify(tmp_path, capsys):
    """A still edge that camera-check finds in the first frame but cannot place on the cylinder: exit 2 and
    valid JSON (no NaN), as identify refuses it."""
    r = MarkerRenderer(CAMERA, MARKER, imaging=IMAGING, seed=2)
    video = write_video(tmp_path / "v.avi", (r.render(0.1 * math.sin(k / 5)) for k in range(40)))
    assert main(["camera-check", str(video), "--seconds", "0.5", "--out", str(tmp_path / "c.png"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames_checked"] == 31 and report["tracked_share"] == 1.0 and "refusal" not in report
    narrow = write_toml(tmp_path / "narrow.toml", {**camera_toml(), "marker": {"radius": 0.01, "distance": 0.25}})
    wall = np.full((480, 640), 100, np.uint8)
    wall[:, 600:] = 200  # a bright bar near the edge of the image: beyond a 1 cm cylinder's silhouette
    cv2.imwrite(str(tmp_path / "bar.png"), wall)
    code = main(["camera-check", str(tmp_path / "bar.png"), "--camera", str(narrow), "--out", str(tmp_path / "c.png"),
                 "--json"])
    captured = capsys.readouterr()
    report = json.loads(captured.out, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
    assert code == 2 and report["found"] is False and report["angle_deg"] is None
    assert "silhouette" in captured.err and len(captured.err.strip().splitlines()) == 1
