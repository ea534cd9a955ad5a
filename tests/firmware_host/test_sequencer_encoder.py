"""End to end on the simulated rig over a real pymodbus RTU transport (loopback socket).

Sequencer + solenoid on a gpiozero mock pin + simulated rig + simulated encoder
server + the Modbus client + identification, in time scaled 5× (a 20 s swing
takes 4 s of wall time).
"""

from __future__ import annotations

import pytest
from sequencer_harness import on_durations

from drivers.button import PushButton
from drivers.clock import ScaledClock
from drivers.encoder import ModbusEncoder
from drivers.sim_encoder import SimEncoderConfig, SimEncoderServer
from drivers.simrig import SimRig
from drivers.solenoid import Solenoid
from firmware_host import Sequencer, SequencerConfig, State
from measurement import Pendulum, Rig
from measurement.reports import result_report

#: the swing at 2× real time: the simulated encoder is polled in real time, so a busy host's stall leaves a gap
#: this many times longer in the record (at 5× a stall beside a busy loop per core left 1.5 swings)
SCALE = 2.0
MAX_ON = 0.5


class Rigged:
    """Everything of one simulated measurement, closed in reverse order."""

    def __init__(self, factory, truth: Pendulum, server_config: SimEncoderConfig, *, capture=20.0,
                 sample_timeout=3.0, button=False):
        self.clock = ScaledClock(SCALE)
        self.rig = truth.rig
        self.solenoid = Solenoid(17, max_on_time=MAX_ON, pin_factory=factory)
        self.sim = SimRig(truth, theta0=0.25, clock=self.clock, duration=capture + 5.0).attach(self.solenoid)
        self.server = SimEncoderServer(self.sim.angle, self.clock, server_config).start()
        self.encoder = ModbusEncoder(self.server.encoder_config(timeout=0.02), self.clock)
        self.button = PushButton(27, bounce_time=None, pin_factory=factory) if button else None
        self.results: list = []
        self.events: list = []
        self.seq = Sequencer(clock=self.clock, solenoid=self.solenoid, sensor=self.encoder, rig=self.rig,
                             sink=self.results.append, button=self.button,
                             config=SequencerConfig(capture_duration=capture, sample_timeout=sample_timeout))
        self.seq.subscribe(self.events.append)

    def path(self):
        return [e.state.value for e in self.events]

    def assert_solenoid_safe(self):
        pin = self.solenoid.pin
        assert not self.solenoid.is_active and pin.state is False and pin.states[-1].state is False
        assert len(on_durations(pin)) == 1 and on_durations(pin)[0] <= MAX_ON + 0.25

    def close(self):
        self.seq.close()
        self.encoder.close()
        self.server.stop()
        self.sim.close()
        if self.button:
            self.button.close()
        self.solenoid.close()


@pytest.fixture
def rigged(factory):
    made = []

    def make(*args, **kwargs):
        r = Rigged(factory, *args, **kwargs)
        made.append(r)
        return r
    yield make
    for r in made:
        r.close()


def test_end_to_end_push_button_measurement_finds_J_within_0_2_percent(rigged):
    rig = Rig(kind="compound", mass=2.0, com_distance=0.3, declared=("viscous",))
    truth = Pendulum(rig, 0.25, {"viscous": {"c": 2e-3}, "quadratic": {"K": 4e-3}})
    r = rigged(truth, SimEncoderConfig(noise_std=2e-5, latency=0.0003, seed=11), button=True)
    r.button.pin.drive_low()
    r.button.pin.drive_high()
    last = r.seq.run_until_settled(timeout=200.0)
    assert last is not None and r.path() == ["ARMED", "RELEASING", "CAPTURING", "IDENTIFYING", "PUBLISHING", "IDLE"]
    (m,) = r.results
    assert m.requested_by == "button"
    assert abs(m.result.J / truth.inertia - 1) < 0.002, result_report(m.result)
    enc = m.result.acquisition["encoder"]
    assert enc["samples"] - enc.get("outside_window", 0) == len(m.trace)
    # nothing lost or garbled on this link: a time-out is only ever a reply a busy host let come late
    assert enc["errors"] == enc["timeouts"] and enc["timeouts"] - enc["stale_replies"] <= 1
    r.assert_solenoid_safe()


def test_lossy_bus_5_percent_dropped_1_percent_crc_still_within_0_2_percent_and_counted(rigged):
    rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    truth = Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 1.2e-4}})
    r = rigged(truth, SimEncoderConfig(drop_rate=0.05, crc_error_rate=0.01, latency=0.0002, seed=5))
    assert r.seq.request_measurement("test")
    r.seq.run_until_settled(timeout=200.0)
    assert r.path()[-1] == "IDLE", r.seq.last_fault
    (m,) = r.results
    assert abs(m.result.J / truth.inertia - 1) < 0.002, result_report(m.result)
    enc = m.result.acquisition["encoder"]
    wire = r.server.counts
    assert enc["timeouts"] > 0 and enc["crc_errors"] > 0
    # what the client counted is what the server did on the wire (± the request in flight at the
    # stop), once the replies a busy host let come after their time-out are set apart
    stale = enc["stale_replies"]
    assert abs(enc["timeouts"] - stale - wire["dropped"]) <= 1
    assert wire["corrupted"] - stale - 1 <= enc["crc_errors"] <= wire["corrupted"] + 1
    assert 0.02 < (enc["errors"] - stale) / enc["requests"] < 0.12
    assert "encoder_errors" in m.result.flags
    assert "encoder" in result_report(m.result) and "crc_errors" in m.result.to_json()
    r.assert_solenoid_safe()


def test_encoder_server_stopped_mid_capture_is_a_fault_with_the_solenoid_off(rigged):
    rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    truth = Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}})
    r = rigged(truth, SimEncoderConfig(seed=2))
    assert r.seq.request_measurement("test")
    while r.seq.poll() is not State.CAPTURING:
        r.clock.sleep(0.01)
    assert r.encoder.wait_for_samples(50, 10.0)
    r.server.stop()
    last = r.seq.run_until_settled(timeout=60.0)
    assert r.path() == ["ARMED", "RELEASING", "CAPTURING", "FAULT"]
    assert last.state is State.FAULT
    assert last.reason.startswith("encoder fault: 10 failed reads in a row from device 1 on socket://127.0.0.1:")
    assert "connection errors" in last.reason
    assert r.seq.status()["last_fault"] == last.reason and r.results == []
    r.assert_solenoid_safe()
