"""Rendered videos of every target and view, encoded to H.264 by Debian's FFmpeg (real codec artefacts):
J within 0.01 % through a letterbox, a static distractor edge, a target lost for a second and a variable
frame rate; bad input refused in one line."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from measurement.vision import CameraModel, CameraPose, Imaging, MarkerGeometry, MarkerRenderer
from measurement.vision.render_plane import PlaneRenderer, PlaneScene
from measurement.vision.target import TargetSpec
from service.cli import main
from tests.components import missing

from .conftest import J_TRUE, RIG, truth_swing, write_toml


@pytest.fixture(autouse=True, scope="module")
def _ffmpeg() -> None:
    if shutil.which("ffmpeg") is None:
        missing("Debian's ffmpeg is not installed (make ffmpeg)")


W, H, FPS = 320, 240, 30.0
DURATION = 10.0


#: frame k of the variable-frame-rate clip is shown at (k + VFR_JITTER·sin(1.7·k))/FPS: FFmpeg's setpts
VFR_JITTER = 0.35


def vfr_times(n: int) -> np.ndarray:
    k = np.arange(n)
    return (k + VFR_JITTER * np.sin(1.7 * k)) / FPS


def encode(path: Path, frames: list[np.ndarray], vfr: bool = False) -> Path:
    """H.264 (libx264, CRF 18) in MP4 at FPS; vfr: frame k presented at ``vfr_times`` (FFmpeg's setpts)."""
    # the filter's time base first: setpts counts in it, and the encoder's and the muxer's must keep it
    timing = (["-vf", f"settb=1/90000,setpts='(N+{VFR_JITTER}*sin(1.7*N))/({FPS:g}*TB)'", "-fps_mode", "passthrough",
               "-enc_time_base:v", "1:90000", "-video_track_timescale", "90000"] if vfr else [])
    cmd = ["ffmpeg", "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "bgr24", "-s", f"{W}x{H}",
           "-framerate", f"{FPS:g}", "-i", "-", *timing, "-c:v", "libx264", "-crf", "18", "-pix_fmt", "yuv420p", str(path)]
    subprocess.run(cmd, input=b"".join(f.tobytes() for f in frames), check=True, timeout=120)
    return path


def camera_file(tmp_path: Path, target: dict) -> Path:
    return write_toml(tmp_path / "cam.toml", {"camera": {"width": W, "height": H, "fps": FPS}, "target": target})


def identify(capsys, video: Path, cam: Path, tmp_path: Path) -> dict:
    rig = write_toml(tmp_path / "rig.toml", RIG.to_dict())
    code = main(["identify", str(video), "--rig", str(rig), "--camera", str(cam), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


def rendered(spec: TargetSpec, scene: PlaneScene, times: np.ndarray, occluded=lambda t: False) -> list[np.ndarray]:
    swing = truth_swing(DURATION + 0.5)
    r = PlaneRenderer(W, H, spec, scene, imaging=Imaging(blur=0.8, noise=1.5), seed=3)
    return [r.render(float(swing.angle(t)), occlude=occluded(t)) for t in times]


def test_tag_face_on_letterboxed_with_a_distractor_edge_at_a_variable_frame_rate(tmp_path, capsys):
    times = vfr_times(int(DURATION * FPS))
    spec = TargetSpec(kind="tag")
    scene = PlaneScene(pivot=(160, 8), radius=140, size=64, letterbox=30, distractor=70)
    video = encode(tmp_path / "tag.mp4", rendered(spec, scene, times), vfr=True)
    out = identify(capsys, video, camera_file(tmp_path, {"kind": "tag"}), tmp_path)
    assert out["J"] == pytest.approx(J_TRUE, rel=1e-4)
    cam = out["acquisition"]["camera"]
    assert "variable frame rate" in cam["timing"] and cam["tracking"]["tracked_share"] == 1.0


def test_blob_face_on_lost_for_a_second_pivot_found(tmp_path, capsys):
    times = np.arange(int(DURATION * FPS)) / FPS
    spec = TargetSpec(kind="blob", colour=(200, 30, 40))
    scene = PlaneScene(pivot=(160, 10), radius=160, size=24)
    frames = rendered(spec, scene, times, occluded=lambda t: 4.0 <= t < 5.0)
    video = encode(tmp_path / "blob.mp4", frames)
    out = identify(capsys, video, camera_file(tmp_path, {"kind": "blob", "colour": [200, 30, 40]}), tmp_path)
    assert out["J"] == pytest.approx(J_TRUE, rel=1e-4)
    cam = out["acquisition"]["camera"]
    assert "marker_lost" in out["flags"] and cam["tracking"]["longest_gap_s"] == pytest.approx(1.0, abs=0.05)
    # a ±0.2 rad arc of 160 px rises by 3 px only: the pivot found from it is good to a tenth of the radius
    # (which scales the angle, and matters only through sin θ on a gravity pendulum)
    assert cam["pivot_fitted"] and abs(cam["pivot_v_px"] - 10) < 16 and abs(cam["pivot_u_px"] - 160) < 3


@pytest.mark.parametrize("target", [{"kind": "blobs", "view": "along-axis", "polarity": "dark"},
                                    {"kind": "patch", "view": "along-axis", "roi": [115, 95, 205, 145]}])
def test_platform_along_the_axis(tmp_path, capsys, target):
    times = np.arange(int(DURATION * FPS)) / FPS
    spec = TargetSpec(kind=target["kind"], view="along-axis")
    scene = PlaneScene(pivot=(160, 120), radius=80, size=22)
    video = encode(tmp_path / "platform.mp4", rendered(spec, scene, times))
    out = identify(capsys, video, camera_file(tmp_path, target), tmp_path)
    assert out["J"] == pytest.approx(J_TRUE, rel=1e-4)
    assert out["acquisition"]["camera"]["corrupt_frames"] == 0


def test_edge_on_a_cylinder_in_h264_has_no_corrupt_frames(tmp_path, capsys):
    camera = CameraModel(width=W, height=H, fps=FPS, fx=300.0, fy=300.0, cx=159.5, cy=119.5)
    marker = MarkerGeometry(radius=0.10, distance=0.25)
    r = MarkerRenderer(camera, marker, pose=CameraPose(), imaging=Imaging(blur=1.0, noise=1.5), seed=4)
    swing = truth_swing(DURATION + 0.5)
    frames = [cv2.cvtColor(r.render(float(swing.angle(t))), cv2.COLOR_GRAY2BGR)
              for t in np.arange(int(DURATION * FPS)) / FPS]
    video = encode(tmp_path / "edge.mp4", frames)
    cam = write_toml(tmp_path / "cam.toml", {"camera": camera.to_dict(), "marker": marker.to_dict()})
    out = identify(capsys, video, cam, tmp_path)
    assert out["J"] == pytest.approx(J_TRUE, rel=1e-4)
    assert out["acquisition"]["camera"]["corrupt_frames"] == 0


@pytest.fixture(scope="module")
def still_and_empty(tmp_path_factory):
    """Two short H.264 clips: a tag that never moves, and the wall without any target."""
    d = tmp_path_factory.mktemp("bad")
    spec = TargetSpec(kind="tag")
    r = PlaneRenderer(W, H, spec, PlaneScene(pivot=(160, 12), radius=150, size=44), imaging=Imaging(0.8, 1.5))
    still = encode(d / "still.mp4", [r.render(0.05) for _ in range(60)])
    empty = PlaneRenderer(W, H, TargetSpec(kind="blobs"), PlaneScene(pivot=(160, 120), radius=1, size=1))
    wall = encode(d / "wall.mp4", [empty._background.clip(0, 255).astype(np.uint8) for _ in range(60)])
    return d, still, wall


def test_bad_input_is_one_line_exit_2(tmp_path, capsys, still_and_empty):
    d, still, wall = still_and_empty
    truncated = tmp_path / "truncated.mp4"
    truncated.write_bytes(still.read_bytes()[: still.stat().st_size // 3])
    empty = tmp_path / "empty.mp4"
    empty.write_bytes(b"")
    garbage = tmp_path / "garbage.mp4"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    cam = camera_file(tmp_path, {"kind": "tag"})
    rig = write_toml(tmp_path / "rig.toml", RIG.to_dict())
    expected = {still: "does not move", wall: "tag", truncated: "", empty: "empty", garbage: "cannot be opened"}
    for video, words in expected.items():
        code = main(["identify", str(video), "--rig", str(rig), "--camera", str(cam)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and words in err[0], (video.name, err)
