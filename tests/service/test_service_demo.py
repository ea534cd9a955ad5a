"""`moi demo` (what `make demo` runs): one push-button measurement on the simulated appliance."""

from __future__ import annotations

import socket

import pytest

from service.cli import main
from service.commands.demo import EXIT_FAULT

# 8 s of swing at 4× real time (2 s of it): the simulated encoder is polled in real time, so the faster the swing
# runs, the fewer polls a busy host answers per swing (at 20× too few were left for 3 swings; 8× passed a busy loop
# on each core with no margin to spare beside the suite's own workers)
FAST = ["--duration", "8", "--time-scale", "4", "--web-port", "0", "--releases", "1"]


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


def test_demo_goes_to_a_free_port_when_its_port_is_taken_at_the_moment_it_binds(capsys, monkeypatch):
    """Another program takes the web port after any check could have seen it free: the demo binds a free port
    instead of stopping."""
    from service.publish.web.server import WebServer

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        wanted = probe.getsockname()[1]
    intruders: list[socket.socket] = []
    start = WebServer.start

    def taken_first(self, *args, **kw):
        if self.settings.port == wanted and not intruders:
            intruder = socket.socket()
            intruder.bind(("127.0.0.1", wanted))
            intruder.listen()
            intruders.append(intruder)
        return start(self, *args, **kw)

    monkeypatch.setattr(WebServer, "start", taken_first)
    try:
        # the last --web-port counts; the swing's own outcome on a loaded host is the other tests' subject
        status = main(["demo", *FAST, "--web-port", str(wanted)])
    finally:
        for s in intruders:
            s.close()
    out = capsys.readouterr().out
    assert len(intruders) == 1 and f"port {wanted} is taken: the web page goes on a free port" in out
    shown = int(out.split("web page: http://127.0.0.1:")[1].split("/")[0])
    assert shown not in (wanted, 0) and "pressing the push button" in out
    assert status in (0, EXIT_FAULT), status  # EXIT_FAULT: the swing itself failed (too few samples, a busy host)
