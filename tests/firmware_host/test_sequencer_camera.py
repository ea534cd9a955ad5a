"""The sequencer capturing from the camera: mock solenoid + SimRig + MockCamera (100 frames/s) + CameraAngleSensor.

Everything on a ManualClock: the mock camera renders the frames the clock
has reached inside ``poll()`` (no thread moves the clock), identification
runs inline. Checks J against the simulated truth with a straight and a
yawed camera (the yaw fitted in the sensor's ``finish`` hook), the faults of
a camera that stops seeing the marker or stops delivering, and the hook
itself on a sensor that is not a camera.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from sequencer_harness import MAX_ON, RIG, TRUTH, assert_solenoid_safe, fake_identify, on_durations

from drivers.camera import MockCamera
from drivers.camera_sensor import CameraAngleSensor
from drivers.clock import ManualClock
from drivers.errors import SensorFault
from drivers.sensor import SimulatedAngleSensor
from drivers.simrig import SimRig
from drivers.solenoid import Solenoid
from firmware_host import Event, Measurement, Sequencer, SequencerConfig, State
from measurement import Trace
from measurement.vision import CameraConfig, CameraModel, CameraPose, Imaging, MarkerGeometry

CAMERA = CameraModel(width=640, height=480, fps=100.0, fx=600.0, fy=600.0, cx=319.5, cy=239.5)
CONFIG = CameraConfig(camera=CAMERA, marker=MarkerGeometry(radius=0.10, distance=0.25))
NORMAL_PATH = ["ARMED", "RELEASING", "CAPTURING", "IDENTIFYING", "PUBLISHING", "IDLE"]


class Covered(MockCamera):
    """A mock camera whose frames are blank from ``covered_from`` s on (lens covered, lamp failed)."""

    covered_from = math.inf

    def grab_ready(self):
        return [f if f.t < self.covered_from else type(f)(f.t, np.full_like(f.image, 90), f.index)
                for f in super().grab_ready()]


class CameraRig:
    """Sequencer + solenoid on a mock pin + SimRig + mock camera + camera sensor, on a ManualClock."""

    def __init__(self, factory, *, yaw_deg=0.0, capture=5.0, camera_cls=MockCamera, identifier=None):
        self.clock = ManualClock()
        self.solenoid = Solenoid(17, max_on_time=MAX_ON, pin_factory=factory)
        self.sim = SimRig(TRUTH, theta0=0.25, clock=self.clock, duration=capture + 5.0).attach(self.solenoid)
        self.camera = camera_cls(CONFIG, self.sim.angle, self.clock, imaging=Imaging(blur=1.0, noise=2.0), seed=5,
                                 pose=CameraPose(yaw=math.radians(yaw_deg)))
        self.sensor = CameraAngleSensor(self.camera, CONFIG, self.clock)
        self.results: list[Measurement] = []
        self.events: list[Event] = []
        self.seq = Sequencer(clock=self.clock, solenoid=self.solenoid, sensor=self.sensor, rig=RIG,
                             sink=self.results.append, identifier=identifier,
                             config=SequencerConfig(capture_duration=capture, identify_in_worker=False))
        self.seq.subscribe(self.events.append)

    def measure(self, max_steps=3000):
        assert self.seq.request_measurement("test")
        for _ in range(max_steps):
            self.clock.advance(0.01)
            if self.seq.poll() in (State.IDLE, State.FAULT) and not self.seq.busy:
                return self.events[-1]
        raise AssertionError(f"no end after {max_steps} polls: {self.path()}")

    def path(self):
        return [e.state.value for e in self.events]

    def close(self):
        self.seq.close()
        self.sensor.close()
        self.sim.close()
        self.solenoid.close()


@pytest.fixture
def camera_rig(factory):
    made = []

    def make(**kwargs) -> CameraRig:
        made.append(CameraRig(factory, **kwargs))
        return made[-1]
    yield make
    for r in made:
        r.close()


@pytest.mark.parametrize("yaw_deg", [0.0, 4.0])
def test_the_camera_measures_J_within_0_2_percent_and_reports_the_yaw(camera_rig, yaw_deg):
    r = camera_rig(yaw_deg=yaw_deg)
    r.measure()
    assert r.path() == NORMAL_PATH, r.events[-1].reason
    (m,) = r.results
    assert abs(m.result.J / TRUTH.inertia - 1) < 0.002
    cam = m.result.acquisition["camera"]
    assert cam["yaw_deg"] == pytest.approx(yaw_deg, abs=0.1) and cam["yaw_corrected"] is True
    assert cam["samples"] - cam.get("outside_window", 0) == cam["frames_used"] == len(m.trace) > 500   # ≥ 5.5 s at 100 frames/s, none lost
    assert cam["marker_lost"] == cam["corrupt_frames"] == cam["dropped_frames"] == 0 and cam["reader"] == "poll"
    assert ("camera_pose" in m.result.flags) is (yaw_deg > 2.0)    # the camera file's limit: 2°
    assert m.trace.source == "camera" and m.to_dict()["acquisition"]["camera"]["yaw_deg"] == cam["yaw_deg"]
    assert m.trace.meta["sequencer"]["measurement_id"] == m.id
    # the release was seen: the held pre-trigger frames, then the swing
    release_t = m.trace.meta["sequencer"]["release_t"]
    held = m.trace.angle[m.trace.t < release_t]
    assert held.size >= 45 and np.ptp(held) < math.radians(0.01)
    assert_solenoid_safe(r)
    assert len(on_durations(r.solenoid.pin)) == 1


def test_a_camera_that_loses_the_marker_for_good_ends_in_fault_with_the_reason(camera_rig):
    r = camera_rig(camera_cls=Covered, identifier=fake_identify, capture=3.0)
    r.camera.covered_from = 1.5   # s on the clock: 0.8 s into the free swing
    last = r.measure()
    assert r.path() == ["ARMED", "RELEASING", "CAPTURING", "FAULT"]
    assert last.reason.startswith("camera fault: no marker in 50 frames in a row (0.5 s at 100 frames/s)")
    assert r.seq.last_fault == last.reason and r.seq.status()["last_fault"] == last.reason
    assert last.time == pytest.approx(1.5 + 0.5, abs=0.02)  # faulted as soon as the run was long enough
    assert r.results == [] and r.seq.counts["faults"] == 1
    assert_solenoid_safe(r)
    # acknowledged, the next measurement with a working camera succeeds
    r.camera.covered_from = math.inf
    assert r.seq.reset()
    r.seq.poll()
    r.sim.relatch()
    r.measure()
    assert r.path()[-6:] == NORMAL_PATH and len(r.results) == 1


def test_a_camera_that_stops_delivering_before_the_release_never_fires_the_solenoid(camera_rig):
    class Unplugged(MockCamera):
        def grab_ready(self):
            if self.stats()["frames"] >= 20:
                raise SensorFault("mock camera: unplugged")
            return super().grab_ready()

    r = camera_rig(camera_cls=Unplugged, identifier=fake_identify)
    last = r.measure()
    assert r.path() == ["ARMED", "FAULT"] and last.reason == "mock camera: unplugged"
    assert r.solenoid.pin.states[-1].state is False and on_durations(r.solenoid.pin) == []
    assert r.sim.released_at is None


def test_the_finish_hook_runs_once_before_identification_and_its_trace_is_published(factory):
    """The hook on a sensor that is not a camera: called once, its trace identified and published."""

    class Finishing(SimulatedAngleSensor):
        calls = []

        def finish(self, trace):
            self.calls.append(len(trace))
            return Trace(trace.t, trace.angle * 2.0, source=trace.source, flags=trace.flags + ("finished",),
                         meta={**trace.meta, "finish": True})

    seen = []

    def identifier(trace, rig):
        seen.append(trace)
        return fake_identify(trace, rig)

    clock = ManualClock()
    with Solenoid(17, max_on_time=MAX_ON, pin_factory=factory) as solenoid:
        sim = SimRig(TRUTH, theta0=0.25, clock=clock, duration=5.0).attach(solenoid)
        sensor = Finishing(sim.angle, clock, rate=100.0)
        results: list[Measurement] = []
        with Sequencer(clock=clock, solenoid=solenoid, sensor=sensor, rig=RIG, sink=results.append,
                       identifier=identifier, config=SequencerConfig(capture_duration=2.0, identify_in_worker=False)) as seq:
            seq.request_measurement("test")
            while not (seq.poll() is State.IDLE and results):
                clock.advance(0.01)
        (m,) = results
        assert Finishing.calls == [len(m.trace)] and seen == [m.trace]
        assert "finished" in m.trace.flags and m.trace.meta["finish"] and m.trace.angle.max() == pytest.approx(0.5, abs=1e-4)

        # a failing hook is a FAULT naming the sensor, with the solenoid off
        def broken(trace):
            raise ValueError("no swing in the record")
        sensor.finish = broken  # type: ignore[method-assign]
        sim.relatch()
        with Sequencer(clock=clock, solenoid=solenoid, sensor=sensor, rig=RIG, sink=results.append,
                       identifier=identifier, config=SequencerConfig(capture_duration=2.0, identify_in_worker=False)) as seq:
            seq.request_measurement("test")
            while seq.poll() is not State.FAULT:
                clock.advance(0.01)
            assert seq.last_fault == "encoder: finishing the capture failed: no swing in the record"
            assert not solenoid.is_active and len(results) == 1
        sim.close()
