"""The configuration file: the examples load, bad files give one clear line and exit status 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from service.cli import main
from service.config.appliance import DEFAULT_SIM_RIG, load_config, parse_config

REPO = Path(__file__).resolve().parents[3]

HARDWARE = """
[device]
rig = "rig.toml"
[hardware]
gpio_backend = "mock"
[hardware.solenoid]
pin = 17
[hardware.encoder]
port = "/dev/ttyUSB0"
"""

RIG = """
[rig]
kind = "torsion"
stiffness = 0.3651
[model]
declared = ["viscous"]
"""


def write(tmp_path: Path, text: str, name: str = "appliance.toml") -> Path:
    (tmp_path / "rig.toml").write_text(RIG)
    p = tmp_path / name
    p.write_text(text)
    return p


def test_the_example_configs_load():
    full = load_config(REPO / "examples" / "appliance.toml")
    assert not full.simulated and full.hardware is not None and full.hardware.solenoid["pin"] == 17
    assert full.mqtt.tls and full.mqtt.port == 8883 and full.modbus.port == 5020
    assert full.rig.kind == "torsion"
    sim = load_config(REPO / "examples" / "appliance.toml", sim=True)
    assert sim.simulated and sim.hardware is not None  # --sim keeps the hardware table validated
    demo = load_config(REPO / "examples" / "appliance-sim.toml")
    assert demo.simulated and demo.mqtt is None and demo.modbus.host == "127.0.0.1"
    assert REPO not in demo.state_dir.parents  # trying the example does not write into the source tree


def test_no_config_means_a_simulated_appliance_without_mqtt(monkeypatch, tmp_path):
    monkeypatch.setenv("STATE_DIRECTORY", str(tmp_path / "st"))
    c = load_config(None)
    assert c.simulated and c.mqtt is None and c.modbus is not None and c.rig == DEFAULT_SIM_RIG
    assert c.state_dir == tmp_path / "st"  # systemd's StateDirectory=


def test_hardware_config_with_the_sim_switch(tmp_path):
    c = load_config(write(tmp_path, HARDWARE))
    assert not c.simulated and c.hardware is not None and c.hardware.encoder is not None
    assert c.hardware.encoder["port"] == "/dev/ttyUSB0"
    assert load_config(write(tmp_path, HARDWARE), sim=True).simulated


def test_relative_paths_are_relative_to_the_config_file(tmp_path):
    c = parse_config({"device": {"state_dir": "data"}}, base=tmp_path)
    assert c.state_dir == tmp_path / "data"


BAD = [
    ("unknown key", "[mqtt]\nhots = 'x'\n", "[mqtt]: unknown key 'hots' (did you mean 'host'?)"),
    ("unknown table", "[mqqt]\nhost = 'x'\n", "unknown table 'mqqt' (did you mean [mqtt]?)"),
    ("bad type", "[mqtt]\nport = '1883'\n", "[mqtt] port: expected an integer in [1, 65535], got '1883'"),
    ("out of range", "[modbus]\nport = 70000\n", "[modbus] port: expected an integer"),
    ("bad choice", "[modbus]\nword_order = 'middle'\n", "[modbus] word_order: expected one of 'big', 'little'"),
    ("bool as number", "[sequencer]\ncapture_duration = true\n", "[sequencer] capture_duration: expected a number"),
    ("sequencer range", "[sequencer]\nrelease_pulse = 0.0\n", "[sequencer]: sequencer: release_pulse = 0.0"),
    ("missing solenoid", "[device]\nrig = 'rig.toml'\n[hardware]\n[hardware.encoder]\nport = 'x'\n",
     "[hardware] solenoid: missing"),
    ("missing pin", "[device]\nrig = 'rig.toml'\n[hardware.solenoid]\nactive_high = true\n[hardware.encoder]\nport = 'x'\n",
     "[hardware.solenoid] pin: missing"),
    ("missing encoder", "[device]\nrig = 'rig.toml'\n[hardware.solenoid]\npin = 17\n",
     "[hardware] encoder: missing"),
    ("missing rig", "[hardware.solenoid]\npin = 17\n[hardware.encoder]\nport = 'x'\n", "[device] rig: missing"),
    ("bad encoder key", HARDWARE + "baud = 9600\n", "[hardware.encoder]: encoder: unknown setting(s) baud"),
    ("bad encoder value", HARDWARE + "parity = 'X'\n", "encoder: parity must be one of N, E, O"),
    ("rig not found", "[device]\nrig = 'nope.toml'\n", "rig file"),
    ("unknown effect", "[simulation.effects]\nsticky = { c = 1.0 }\n", "unknown effect 'sticky'"),
    ("bad effect parameter", "[simulation.effects]\nviscous = { q = 1.0 }\n", "viscous: missing value; expected one of c_per_J, c"),
    ("rtu without port", "[modbus]\nmode = 'rtu'\n", "[modbus] serial_port: missing"),
    ("password without user", "[mqtt]\npassword = 'x'\n", "[mqtt] username: missing"),
    ("tls files without tls", "[mqtt]\nca_file = 'ca.pem'\n", "[mqtt] tls:"),
    ("device id with slash", "[device]\nid = 'a/b'\n", "[device] id:"),
    ("not toml", "[mqtt\nhost=1\n", "is not valid TOML"),
    ("table is a value", "mqtt = 3\n", "[mqtt]: expected a table"),
]


@pytest.mark.parametrize(("name", "text", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_config_is_one_clear_line_and_exit_2(tmp_path, capsys, name, text, message):
    path = write(tmp_path, text)
    assert main(["run", "--config", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    err = captured.err
    assert err.count("\n") == 1, err  # one line, no traceback
    assert err.startswith("moi run: error: ") and str(path) in err
    assert message in err, err


def test_a_missing_config_file_is_one_line(tmp_path, capsys):
    assert main(["run", "--config", str(tmp_path / "absent.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not found" in err


def test_check_prints_the_configuration_without_secrets(tmp_path, capsys):
    path = write(tmp_path, "[mqtt]\nusername = 'moi'\npassword = 'hunter2'\n")
    assert main(["run", "--config", str(path), "--check", "--json"]) == 0
    out = capsys.readouterr().out
    assert '"simulated": true' in out and "hunter2" not in out and '"***"' in out


def test_the_configuration_reference_in_docs_matches_the_schema():
    from service.config.appliance import reference_markdown

    text = (REPO / "docs" / "service.md").read_text(encoding="utf-8")
    start = text.index("-->\n", text.index("<!-- config-reference:start")) + 4
    end = text.index("<!-- config-reference:end -->")
    assert text[start:end] == reference_markdown(), "docs/service.md is stale: regenerate with `moi run --config-reference`"
