"""`moi measure --config FILE`: one measurement on the devices of a configuration (commissioning), built by
the daemon's own device builder; here on the simulated rig a configuration without [hardware] gives."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from service.cli import main

# a measurement on the simulated rig, its encoder on a pymodbus bus in wall-clock time
pytestmark = pytest.mark.clock

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def fresh_mock_pins():
    """The mock pins remember every state they had: later tests count the solenoid's pulses."""
    yield
    from gpiozero import Device
    if Device.pin_factory is not None:
        Device.pin_factory.reset()


def config(tmp_path: Path, extra: str = "") -> Path:
    cfg = tmp_path / "appliance.toml"
    cfg.write_text(f'[device]\nstate_dir = "{tmp_path / "state"}"\n[sequencer]\npre_trigger = 0.2\n'
                   f'capture_duration = 5.0\n[simulation]\ntime_scale = 25.0\nrate = 100.0\nsensor = "direct"\n'
                   + extra)
    return cfg


def test_measure_config_runs_one_measurement_with_the_configured_devices(tmp_path, capsys):
    assert main(["measure", "--config", str(config(tmp_path)), "--json"]) == 0
    captured = capsys.readouterr()
    d = json.loads(captured.out)
    assert abs(d["J"] / 0.0125 - 1) < 2e-3 and d["requested_by"] == "cli"
    assert "IDLE" in captured.err and not (tmp_path / "state" / "results.db").exists()  # nothing stored
    # the simulated clock runs 25x: state lines show the wall time, the simulated clock labelled, and that it is identifying
    assert "(simulated clock" in captured.err and "identifying…" in captured.err


def test_measure_config_refuses_bad_pins_and_a_running_daemon(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(f'[device]\nstate_dir = "{tmp_path / "state"}"\nrig = "{REPO / "examples" / "torsion_rig.toml"}"\n'
                   '[hardware]\ngpio_backend = "mock"\nsolenoid = { pin = "BANANA" }\n'
                   'encoder = { port = "socket://127.0.0.1:1" }\n')
    assert main(["measure", "--config", str(bad)]) == 2
    assert "'BANANA' is not a GPIO pin" in capsys.readouterr().err

    from service.persistence.state_dir import lock_state_dir
    fd = lock_state_dir(tmp_path / "state")  # the daemon holds the state directory
    try:
        assert main(["measure", "--config", str(config(tmp_path))]) == 3
        assert "another moi daemon" in capsys.readouterr().err
    finally:
        os.close(fd)
