"""`moi identify EXPORT`: another tool's file as SOURCE, its releases listed and one picked with --release."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from measurement.result import SCHEMA_VERSION
from service.cli import main
from service.sources.formats.registry import describe

from ..service.sources.test_service_formats import phyphox_log
from ..service.sources.test_service_trk import AXES, MODEL, bob, mark, point_mass, project

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def rig(tmp_path):
    f = tmp_path / "rig.toml"
    f.write_text('[rig]\nkind = "compound"\nlength = 0.5066\n\n[model]\ndeclared = ["viscous"]\n')
    return str(f)


def test_the_help_lists_every_format_with_an_example_and_the_rate_format(capsys):
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    out = capsys.readouterr().out
    assert "t,rate (rad/s)" in out and "--release N" in out
    for name, _, example in describe():
        assert f"  {name}: " in out and example in out


def test_one_release_of_a_phyphox_log_is_picked_and_its_period_and_g_given(tmp_path, rig, capsys):
    phyphox_log(tmp_path / "log", n=2)
    assert main(["identify", str(tmp_path / "log"), "--release", "2", "--rig", rig, "--json",
                 "--no-discover"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["schema"] == SCHEMA_VERSION and d["measures"] == "rate"
    assert d["acquisition"]["release"]["number"] == 2 and d["acquisition"]["release"]["of"] == 2
    assert d["acquisition"]["axis"]["swing_about"] == "Gyroscope x (rad/s)"
    p = d["periods"]
    # the simulated swing is a linear one at 4.4 rad/s: counted over the record its period is the swing's own;
    # the compound rig's sin θ law reads it as a faster small swing, slower at its largest (0.4 rad)
    assert p["amplitude"] == pytest.approx(0.4, rel=0.03)
    assert p["counted"] == pytest.approx(2 * 3.141592653589793 / 4.4, rel=2e-3)
    assert p["small_swing"] < p["counted"] < p["at_amplitude"]
    assert p["g"] == pytest.approx(d["omega_n"] ** 2 * 0.5066, rel=1e-9)


def test_a_rate_record_s_report_speaks_in_rad_per_s(tmp_path, rig, capsys):
    phyphox_log(tmp_path / "log", n=1)
    assert main(["identify", str(tmp_path / "log"), "--rig", rig, "--no-discover"]) == 0
    out = capsys.readouterr().out
    assert "residual [rad/s]" in out and "noise floor" in out and "rad/s; residual/noise" in out
    assert "RMS " in out and " rad/s = " in out
    assert "release.free_swing_from" in out and "period       =" in out


def test_a_release_beyond_those_found_is_refused_in_one_line(tmp_path, rig, capsys):
    phyphox_log(tmp_path / "log", n=2)
    assert main(["identify", str(tmp_path / "log"), "--release", "3", "--rig", rig]) == 2
    assert "hold 2 release(s); expected 1 to 2" in capsys.readouterr().err


def test_a_tracker_project_s_track_named_by_xy_is_identified(tmp_path, rig, capsys):
    still = point_mass("pivot mark", {12 + 2 * k: mark(12 + 2 * k, angle=0.0) for k in range(0, 900, 5)})
    f = project(tmp_path / "pendulum.trk", AXES, bob(), still)
    assert main(["identify", str(f), "--xy", "bob", "--rig", rig, "--json", "--no-discover"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["measures"] == "angle" and d["acquisition"]["log"]["format"] == "tracker-trk"
    assert d["acquisition"]["position"]["radius"] == pytest.approx(0.9, rel=1e-6)
    # the marks follow a swing at 4.4 rad/s sampled at the clip's 30 steps per second
    assert d["periods"]["counted"] == pytest.approx(2 * 3.141592653589793 / 4.4, rel=2e-3)


def test_a_tracker_project_without_marks_exits_2_in_one_line(tmp_path, rig, capsys):
    f = project(tmp_path / "model.trk", AXES, MODEL)
    assert main(["identify", str(f), "--rig", rig]) == 2
    err = capsys.readouterr().err.strip()
    assert "without marked positions inside" in err and len(err.splitlines()) == 1
