"""Rendered videos identified end to end: `moi identify VIDEO --rig --camera`, image folders, damaged input."""

import json
import math

import cv2
import numpy as np
import pytest

from measurement import identify
from measurement.vision import MarkerRenderer
from service.cli import main
from service.sources.files import read_rig
from service.sources.video import video_trace

from .conftest import CAMERA, CONFIG, FPS, IMAGING, J_TRUE, MARKER, RIG, camera_toml, truth_swing, write_toml, write_video


def identify_json(capsys, video, rig, cam):
    assert main(["identify", str(video), "--rig", str(rig), "--camera", str(cam), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_video_identified_end_to_end_J_within_0_1_percent(swing_video, capsys):
    out = identify_json(capsys, swing_video.video, swing_video.rig_file, swing_video.camera_file)
    assert out["J"] == pytest.approx(J_TRUE, rel=1e-3)
    assert out["J"] == pytest.approx(J_TRUE, rel=1e-4)  # what it really does (MJPG at quality 95)
    cam = out["acquisition"]["camera"]
    assert cam["frames"] == cam["frames_used"] == 1200
    assert abs(cam["yaw_deg"]) < 0.1 and cam["yaw_corrected"]
    assert "camera_pose" not in out["flags"] and "marker_lost" not in out["flags"]
    assert "on the 60 frames/s grid" in cam["timing"]


def test_video_angles_match_the_truth(swing_video):
    trace = video_trace(swing_video.video, swing_video.camera_file)
    assert np.allclose(trace.t, np.arange(1200) / 60.0, atol=1e-12)
    err = trace.angle - swing_video.swing.angle(trace.t)
    err -= np.mean(err)  # the zero is the identification's business
    # MJPG compression adds a little to the 0.001° of the raw frames
    assert math.degrees(float(np.sqrt(np.mean(err**2)))) < 0.01


def test_yawed_camera_estimated_within_1_degree_J_within_0_2_percent(yawed_swing_video, capsys):
    v = yawed_swing_video
    out = identify_json(capsys, v.video, v.rig_file, v.camera_file)
    cam = out["acquisition"]["camera"]
    assert cam["yaw_deg"] == pytest.approx(4.0, abs=1.0)
    assert cam["yaw_deg"] == pytest.approx(4.0, abs=0.05)  # what it really does
    assert out["J"] == pytest.approx(J_TRUE, rel=2e-3)
    assert "camera_pose" in out["flags"]  # 4° is over the default 2° limit
    assert "unmodeled_residual" not in out["flags"]


def test_yaw_limit_and_switching_the_correction_off(yawed_swing_video, tmp_path, capsys):
    v = yawed_swing_video
    lenient = write_toml(tmp_path / "lenient.toml", camera_toml(yaw_limit_deg=5.0))
    out = identify_json(capsys, v.video, v.rig_file, lenient)
    assert "camera_pose" not in out["flags"]
    off = write_toml(tmp_path / "off.toml", camera_toml(estimate=False))
    trace = video_trace(v.video, off)
    assert trace.meta["camera"]["yaw_corrected"] is False and trace.meta["camera"]["yaw_deg"] == 0.0
    naive = identify(trace, read_rig(v.rig_file))
    assert "unmodeled_residual" in naive.flags  # the asymmetry the yaw leaves shows in the residual


def occlude(img):
    out = img.copy()
    out[150:330, 200:450] = 128
    return out


def short_swing_frames(n, seed, lost=(), renderer=None):
    swing = truth_swing(8.0)
    r = renderer or MarkerRenderer(CAMERA, MARKER, imaging=IMAGING, seed=seed)
    for k in range(n):
        img = r.render(swing.angle(k / FPS))
        yield occlude(img) if k in lost else img


def corrupt_mjpeg_frames(path, scrambled, headless):
    """Damage JPEG frames inside the AVI: scramble the coded data of one (FFmpeg conceals it by
    repeating the previous frame), wipe the header of another (FFmpeg fails it)."""
    data = bytearray(path.read_bytes())
    starts = [i for i in range(len(data) - 1) if data[i] == 0xFF and data[i + 1] == 0xD8]
    i = starts[scrambled] + 1500
    data[i:i + 2000] = np.random.default_rng(0).integers(0, 256, 2000, dtype=np.uint8).tobytes()
    j = starts[headless]
    data[j:j + 600] = bytes(600)
    path.write_bytes(bytes(data))


def test_lost_marker_and_corrupt_frame_leave_gaps_and_flags(tmp_path, capsys):
    lost = {100, 101, 102, 103, 104}
    video = write_video(tmp_path / "damaged.avi", short_swing_frames(420, 21, lost))
    corrupt_mjpeg_frames(video, scrambled=200, headless=300)
    cam = write_toml(tmp_path / "cam.toml", camera_toml())
    trace = video_trace(video, cam)
    meta = trace.meta["camera"]
    assert meta["frames"] == 420
    # the headless frame does not decode; the scrambled one decodes to a concealed picture, caught either by
    # its rows repeating the previous frame's or as a jump of the track
    assert meta["undecodable_frames"] == 1 and meta["codec"] == "mjpeg" and meta["frames_listed"] == 420
    assert meta["corrupt_frames"] + meta["tracking"]["jumps"] == 2
    assert meta["marker_lost"] == 5 and meta["dropped_frames"] == 0
    assert set(trace.flags) >= {"marker_lost", "corrupt_frame"} and "dropped_frames" not in trace.flags
    missing = sorted(set(range(420)) - set(np.rint(trace.t * CAMERA.fps).astype(int)))
    assert missing == sorted(lost | {200, 300})
    err = trace.angle - truth_swing(8.0).angle(trace.t)
    assert math.degrees(float(np.max(np.abs(err - np.median(err))))) < 0.02  # no stale frame got in
    rig = write_toml(tmp_path / "rig.toml", RIG.to_dict())
    out = identify_json(capsys, video, rig, cam)
    assert {"marker_lost", "corrupt_frame"} <= set(out["flags"])
    assert out["J"] == pytest.approx(J_TRUE, rel=1e-3)


def test_image_folder_with_timestamps_a_broken_file_and_dropped_frames(tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    keep = [k for k in range(300) if k not in (50, 51, 52)]  # three frames never arrived
    frames = dict(enumerate(short_swing_frames(300, 22)))
    lines = ["file,t"]
    for k in keep:
        name = f"img{k}.png"  # natural order: img2 before img10
        cv2.imwrite(str(folder / name), frames[k])
        lines.append(f"{name},{k / FPS + 3.0:.9f}")
    (folder / "img120.png").write_bytes((folder / "img120.png").read_bytes()[:300])  # truncated file
    (folder / "timestamps.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    trace = video_trace(folder, CONFIG)
    meta = trace.meta["camera"]
    assert meta["frames"] == 297 and meta["corrupt_frames"] == 1 and meta["dropped_frames"] == 3
    assert {"corrupt_frame", "dropped_frames"} <= set(trace.flags)
    assert trace.t[0] == pytest.approx(3.0)
    err = trace.angle - truth_swing(8.0).angle(trace.t - 3.0)
    assert math.degrees(float(np.max(np.abs(err - np.mean(err))))) < 0.01
    # without timestamps.csv the frames are 1/fps apart
    (folder / "timestamps.csv").unlink()
    plain = video_trace(folder, CONFIG)
    assert np.allclose(np.diff(plain.t)[:5], 1 / 60)


def test_millisecond_container_times_snap_to_the_frame_grid(tmp_path):
    path = tmp_path / "clip.mkv"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"FFV1"), 60.0, (640, 480), isColor=False)
    for img in short_swing_frames(90, 23):
        w.write(img)
    w.release()
    raw = cv2.VideoCapture(str(path))
    stamps = []
    while raw.grab():
        stamps.append(raw.get(cv2.CAP_PROP_POS_MSEC))
    raw.release()
    assert stamps[1] == 17.0  # Matroska keeps whole milliseconds
    trace = video_trace(path, CONFIG)
    assert np.allclose(trace.t, np.arange(90) / 60.0, atol=1e-12)
    assert "grid" in trace.meta["camera"]["timing"]


def test_video_of_the_wrong_size_is_an_input_error(tmp_path, capsys):
    small = tmp_path / "small.avi"
    w = cv2.VideoWriter(str(small), cv2.VideoWriter.fourcc(*"MJPG"), 60.0, (320, 240), isColor=False)
    for _ in range(5):
        w.write(np.zeros((240, 320), np.uint8))
    w.release()
    cam = write_toml(tmp_path / "cam.toml", camera_toml())
    rig = write_toml(tmp_path / "rig.toml", RIG.to_dict())
    assert main(["identify", str(small), "--rig", str(rig), "--camera", str(cam)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "320×240 px" in err[0] and "640×480" in err[0]


def test_video_without_a_marker_is_an_input_error(tmp_path, capsys):
    blank = write_video(tmp_path / "blank.avi", (np.full((480, 640), 100, np.uint8) for _ in range(30)))
    cam = write_toml(tmp_path / "cam.toml", camera_toml())
    rig = write_toml(tmp_path / "rig.toml", RIG.to_dict())
    assert main(["identify", str(blank), "--rig", str(rig), "--camera", str(cam)]) == 2
    err = capsys.readouterr().err
    assert "target was found in 0 of 30 frames" in err and "camera-check" in err


def test_missing_video_and_empty_folder(tmp_path):
    from measurement.errors import InvalidInput

    with pytest.raises(InvalidInput, match="not found"):
        video_trace(tmp_path / "nope.avi", CONFIG)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InvalidInput, match="holds no images"):
        video_trace(tmp_path / "empty", CONFIG)
