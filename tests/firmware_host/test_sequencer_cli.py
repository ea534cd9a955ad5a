"""`moi measure --sim`: one push-button cycle on the simulated rig, through the real CLI entry point."""

import json

from service.cli import main


def test_measure_sim_prints_every_state_and_the_result(capsys):
    rc = main(["measure", "--sim", "--duration", "12", "--time-scale", "8", "--seed", "1"])
    out = capsys.readouterr().out
    assert rc == 0, out
    states = [line.split()[3] for line in out.splitlines() if line.startswith("[") and " s] " in line]
    assert states == ["ARMED", "RELEASING", "CAPTURING", "IDENTIFYING", "PUBLISHING", "IDLE"]
    assert "pressing the button" in out and "1 pulse(s)" in out and "now off" in out
    assert "[[Result]]" in out and "true J 0.0125 kg·m² → error" in out
    error = float(out.split("→ error")[1].split("%")[0])
    assert abs(error) < 0.2


def test_measure_sim_json_on_a_lossy_bus(capsys):
    rc = main(["measure", "--sim", "--duration", "10", "--time-scale", "8", "--drop-rate", "0.05",
               "--crc-rate", "0.01", "--seed", "4", "--json", "--effects", "viscous=3e-4"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    d = json.loads(captured.out)
    assert abs(d["J"] / d["truth"]["J"] - 1) < 0.002
    assert d["acquisition"]["encoder"]["timeouts"] > 0 and "encoder_errors" in d["flags"]
    assert d["requested_by"] == "button" and d["timing"]["capture_end"].startswith("capture complete")
    assert "IDLE" in captured.err  # the states go to stderr with --json


def test_measure_without_sim_is_a_one_line_input_error(capsys):
    assert main(["measure"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--sim" in err


def test_measure_with_an_unknown_effect_is_an_input_error(capsys):
    assert main(["measure", "--sim", "--effects", "magic=1"]) == 2
    assert "unknown effect 'magic'" in capsys.readouterr().err


def test_measure_sim_with_the_camera_fits_the_yaw_and_finds_J(capsys, tmp_path):
    cam = tmp_path / "camera.toml"
    cam.write_text("[camera]\nwidth = 640\nheight = 480\nfps = 30.0\nfx = 600.0\nfy = 600.0\ncx = 319.5\ncy = 239.5\n"
                   "distortion = [0.0, 0.0, 0.0, 0.0, 0.0]\n[marker]\nradius = 0.10\ndistance = 0.25\n",
                   encoding="utf-8")
    rc = main(["measure", "--sim", "--sensor", "camera", "--camera", str(cam), "--camera-yaw", "3",
               "--duration", "6", "--time-scale", "2", "--seed", "2", "--json"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "simulated camera: 640×480 px at 30 frames/s, yaw 3°" in captured.err
    states = [line.split()[3] for line in captured.err.splitlines() if line.startswith("[") and " s] " in line]
    assert states == ["ARMED", "RELEASING", "CAPTURING", "IDENTIFYING", "PUBLISHING", "IDLE"]
    d = json.loads(captured.out)
    assert abs(d["J"] / d["truth"]["J"] - 1) < 0.002
    camera = d["acquisition"]["camera"]
    assert abs(camera["yaw_deg"] - 3.0) < 0.2 and camera["yaw_corrected"] is True and "camera_pose" in d["flags"]
    assert d["acquisition"]["sensor"] == "camera" and "encoder" not in d["acquisition"]


def test_measure_sim_camera_options_are_checked(capsys):
    assert main(["measure", "--sim", "--sensor", "camera", "--camera-yaw", "45"]) == 2
    assert "--camera-yaw must be within ±20°" in capsys.readouterr().err
    assert main(["measure", "--sim", "--sensor", "camera", "--camera", "/nonexistent/cam.toml"]) == 2
    assert "cam.toml" in capsys.readouterr().err
