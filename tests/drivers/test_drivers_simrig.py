"""The simulated rig: held at θ0 until the mock solenoid fires, then the physics."""

import math

import numpy as np
import pytest

from drivers.clock import ManualClock
from drivers.errors import DriverConfigError, SensorFault
from drivers.sensor import SimulatedAngleSensor
from drivers.simrig import SimRig
from drivers.solenoid import Solenoid
from measurement import Pendulum, Rig, Swing

RIG = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
TRUTH = Pendulum(RIG, 0.0125, {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 1.2e-4}})


def test_held_until_the_solenoid_fires_then_swings_by_the_physics(factory):
    clock = ManualClock(100.0)
    with Solenoid(17, max_on_time=0.2, pin_factory=factory) as sol, \
            SimRig(TRUTH, theta0=0.25, clock=clock, duration=10.0).attach(sol) as rig:
        clock.advance(3.0)
        assert (rig.angle(clock.now()), rig.released_at) == (0.25, None)
        sol.pulse(0.1)
        released = clock.now()
        assert rig.released_at == released and rig.releases == 1
        swing = Swing(TRUTH, theta0=0.25, duration=10.0)
        for dt in (0.1, 0.5, 2.0, 7.3):
            assert rig.angle(released + dt) == pytest.approx(swing.angle(dt), abs=1e-9)
        assert rig.angle(released - 1.0) == 0.25  # before the release: still held
        sol.off()
        clock.advance(1.0)
        sol.pulse(0.1)  # a second firing does not restart a swing in progress
        assert rig.released_at == released
        rig.relatch()
        assert rig.angle(clock.now()) == 0.25
        sol.off()
    assert rig.truth()["J"] == 0.0125


def test_rig_settings_are_validated():
    with pytest.raises(DriverConfigError, match="theta0"):
        SimRig(TRUTH, theta0=0.0, clock=ManualClock())
    with pytest.raises(DriverConfigError, match="duration"):
        SimRig(TRUTH, theta0=0.2, clock=ManualClock(), duration=-1)


def test_simulated_sensor_samples_on_the_clock_only():
    clock = ManualClock()
    sensor = SimulatedAngleSensor(lambda t: math.sin(t), clock, rate=100.0, quantisation_bits=17)
    assert sensor.read()[0].size == 0  # not started
    sensor.start()
    clock.advance(0.5)
    t, a = sensor.read()
    assert t.size == 51 and np.allclose(np.diff(t), 0.01)
    assert np.max(np.abs(a - np.sin(t))) <= math.pi / 2**17
    assert sensor.read()[0].size == 0  # nothing new without time passing
    sensor.stall()
    clock.advance(1.0)
    assert sensor.read()[0].size == 0
    sensor.inject_fault("encoder fault: test")
    with pytest.raises(SensorFault, match="encoder fault: test"):
        sensor.read()
    sensor.start()  # a new capture clears the fault
    clock.advance(0.1)
    assert sensor.read()[0].size == 11
    assert sensor.stats()["samples"] == 11
