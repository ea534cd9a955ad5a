"""The camera file: what is accepted, and one clear line for everything that is not."""

import copy
import subprocess
import sys

import pytest

from measurement.errors import InvalidInput, VisionError
from measurement.vision import CameraConfig
from service.cli import main
from service.sources.camera import read_camera

from .conftest import RIG, camera_toml, write_toml

GOOD = camera_toml()


def with_change(table, key, value):
    doc = copy.deepcopy(GOOD)
    if value is None:
        del doc[table][key]
    else:
        doc[table][key] = value
    return doc


def test_round_trip_and_defaults():
    cfg = CameraConfig.from_dict(GOOD)
    assert cfg.camera.width == 640 and cfg.camera.fx == 600.0 and cfg.camera.distortion == (0.0,) * 5
    assert cfg.marker is not None and cfg.marker.radius == 0.10 and cfg.marker.distance == 0.25
    assert cfg.pose.estimate is True and cfg.pose.yaw_limit_deg == 2.0
    doc = copy.deepcopy(GOOD)
    doc["pose"] = {"yaw_limit_deg": 0.5, "estimate": False}
    cfg = CameraConfig.from_dict(doc)
    assert (cfg.pose.yaw_limit_deg, cfg.pose.estimate) == (0.5, False)


@pytest.mark.parametrize(("doc", "words"), [
    (with_change("camera", "fx", None), "[camera] is missing fx"),
    (with_change("marker", "radius", None), "[marker] is missing radius"),
    (with_change("camera", "fx", "600"), "fx must be a number"),
    (with_change("camera", "width", 640.0), "width must be a whole number"),
    (with_change("camera", "height", 0), "height must be a whole number > 0"),
    (with_change("camera", "fps", -30.0), "fps must be > 0"),
    (with_change("marker", "distance", 0.0), "distance must be > 0 m"),
    (with_change("marker", "radius", True), "radius must be a number"),
    (with_change("camera", "distortion", [0.1, 0.0]), "distortion must be a list of 5 numbers"),
    (with_change("camera", "distortion", [0.1, 0.0, 0.0, "x", 0.0]), "distortion[3] must be a number"),
    (with_change("camera", "cx", 700.0), "principal point"),
    (with_change("camera", "focal", 3.0), "unknown key(s) in [camera]: ['focal']"),
    (with_change("marker", "width", 0.02), "unknown key(s) in [marker]"),
    ({**GOOD, "lens": {}}, "unknown table(s) ['lens']"),
    ({"camera": GOOD["camera"]}, "missing [marker] table"),
    ({**GOOD, "pose": {"yaw_limit_deg": -1.0}}, "yaw_limit_deg must be > 0"),
    ({**GOOD, "pose": {"estimate": "yes"}}, "estimate must be true or false"),
])
def test_bad_camera_file_says_what_is_wrong(doc, words):
    with pytest.raises(VisionError) as err:
        CameraConfig.from_dict(doc)
    assert words in str(err.value)
    assert isinstance(err.value, InvalidInput)


def test_read_camera_names_the_file(tmp_path):
    path = write_toml(tmp_path / "cam.toml", with_change("camera", "fy", -1.0))
    with pytest.raises(VisionError, match=r"cam\.toml: camera file: \[camera\] fy must be > 0"):
        read_camera(path)
    (tmp_path / "broken.toml").write_text("[camera\nwidth = 3", encoding="utf-8")
    with pytest.raises(InvalidInput, match="not valid TOML"):
        read_camera(tmp_path / "broken.toml")


def test_cli_bad_camera_file_is_one_line_exit_2(tmp_path, capsys):
    (tmp_path / "swing.avi").write_bytes(b"not a video")
    cam = write_toml(tmp_path / "cam.toml", with_change("marker", "distance", None))
    rig = write_toml(tmp_path / "rig.toml", RIG.to_dict())
    assert main(["identify", str(tmp_path / "swing.avi"), "--rig", str(rig), "--camera", str(cam)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "[marker] is missing distance" in err[0]


def test_cli_undecodable_video_is_one_line_exit_2(tmp_path):
    (tmp_path / "swing.avi").write_bytes(b"not a video")
    cam = write_toml(tmp_path / "cam.toml", GOOD)
    rig = write_toml(tmp_path / "rig.toml", RIG.to_dict())
    proc = subprocess.run([sys.executable, "-m", "service.cli", "identify", str(tmp_path / "swing.avi"),
                           "--rig", str(rig), "--camera", str(cam)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "cannot be opened" in proc.stderr
