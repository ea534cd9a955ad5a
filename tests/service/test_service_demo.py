"""`moi demo` (what `make demo` runs): one push-button measurement on the simulated appliance."""

from __future__ import annotations

import pytest

from service.cli import main

FAST = ["--duration", "6", "--time-scale", "20", "--web-port", "0", "--releases", "1"]


def test_demo_without_a_broker_measures_shows_the_registers_and_skips_mqtt(capsys):
    assert main(["demo", *FAST]) == 0
    out = capsys.readouterr().out
    assert "MQTT: skipped, no broker configured" in out
    assert "pressing the push button" in out and "PUBLISHING" in out
    assert "[[Result]]" in out and "true J 0.0125 kg·m²" in out
    assert "Modbus registers read back over TCP (seq 1" in out
    # the part and its verdict, in the registers too (one release here: the encoder link in real time is slow)
    assert "recipe demo-part" in out and "release 1 of 1" in out and "  release 1: J = " in out
    assert "part DEMO-0001: J = " in out and "→ VERDICT " in out and "part_id        DEMO-0001" in out
    assert "web page: http://127.0.0.1:" in out and "the result page: http://127.0.0.1:" in out


@pytest.mark.broker
def test_demo_with_a_broker_receives_its_result_back(broker, capsys):
    assert main(["demo", *FAST, "--mqtt", f"127.0.0.1:{broker.port}"]) == 0
    out = capsys.readouterr().out
    assert f"MQTT: broker 127.0.0.1:{broker.port}" in out
    assert "received back from the broker" in out
