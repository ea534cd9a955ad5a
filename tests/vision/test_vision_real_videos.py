"""Real videos filmed by other people (data/video/, provenance in data/README.md): each target tracked in
nearly every frame, ω_n within 0.2 % of an independent tracker's, a clip too short refused in one line."""

import json
from pathlib import Path

import pytest

from service.cli import main
from service.sources.camera import read_camera
from service.sources.video import track_source

VIDEOS = Path(__file__).resolve().parents[2] / "data" / "video"


def identify(capsys, name: str, rig: str) -> dict:
    code = main(["identify", str(VIDEOS / f"{name}.mp4"), "--rig", str(VIDEOS / rig),
                 "--camera", str(VIDEOS / f"{name}.toml"), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


@pytest.mark.parametrize(("name", "omega_independent"), [("bartek_film2_vga", 3.9296), ("juangomez_pendulum", 2.3935)])
def test_bob_on_a_string_omega_n_within_0_2_percent(capsys, name, omega_independent):
    out = identify(capsys, name, "pendulum_rig.toml")
    assert out["omega_n"] == pytest.approx(omega_independent, rel=2e-3)
    tracking = out["acquisition"]["camera"]["tracking"]
    assert tracking["tracked_share"] >= 0.9
    assert out["acquisition"]["camera"]["pivot_fitted"] is True


def test_ball_video_frames_listed_but_not_shown_are_said(capsys):
    config = read_camera(VIDEOS / "bartek_film2_vga.toml")
    tracking, source = track_source(VIDEOS / "bartek_film2_vga.mp4", config, seconds=1.0)
    assert source.codec == "h264" and not source.intra_only
    assert source.listed == 2057  # the container's own count; only 1844 lie inside its edit list
    assert tracking.corrupt == 0 and len(tracking.t) >= 0.9 * tracking.frames


def test_trifilar_platform_tracked_in_90_percent_with_a_region(capsys):
    config = read_camera(VIDEOS / "trifilar_table.toml")
    tracking, source = track_source(VIDEOS / "trifilar_table.mp4", config)
    distinct = source.decoded - tracking.repeated
    assert tracking.repeated > 0 and tracking.corrupt == 0  # repeated pictures are not damage
    assert len(tracking.t) >= 0.9 * distinct


def test_three_second_clock_clip_refused_in_one_line(capsys):
    code = main(["identify", str(VIDEOS / "katie_pendula.mp4"), "--rig", str(VIDEOS / "pendulum_rig.toml"),
                 "--camera", str(VIDEOS / "katie_pendula.toml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "swing" in err[0]
