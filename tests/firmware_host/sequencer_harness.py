"""Test harness of the sequencer tests: a sequencer on mock pins, a simulated rig and a simulated sensor, all on a ManualClock (no wall-clock waits)."""

from __future__ import annotations

import threading
from types import SimpleNamespace

from gpiozero.pins.mock import MockFactory

from drivers.clock import ManualClock
from drivers.sensor import SimulatedAngleSensor
from drivers.simrig import SimRig
from drivers.solenoid import Solenoid
from firmware_host import Sequencer, SequencerConfig, State
from measurement import Pendulum, Rig

RIG = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
TRUTH = Pendulum(RIG, 0.0125, {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 1.2e-4}})
MAX_ON = 0.5  # s, the solenoid's hard limit in these tests


def fake_result(J=0.0125):
    """Stands in for an IdentificationResult where the state machine, not the fit, is under test."""
    return SimpleNamespace(J=J, J_std=1e-6, omega_n=5.4, flags=(), acquisition={},
                           to_dict=lambda: {"J": J, "J_std": 1e-6, "omega_n": 5.4})


def fake_identify(trace, rig):
    return fake_result()


class Blocking:
    """An identifier that blocks until released (worker-mode tests); never longer than 30 s."""

    def __init__(self, outcome=None):
        self.release = threading.Event()
        self.started = threading.Event()
        self.outcome = outcome

    def __call__(self, trace, rig):
        self.started.set()
        self.release.wait(30.0)
        if isinstance(self.outcome, BaseException):
            raise self.outcome
        return fake_result()


class Harness:
    """Sequencer + mock solenoid + simulated rig + in-process sensor on a ManualClock."""

    def __init__(self, factory: MockFactory, *, config: SequencerConfig | None = None, identifier=fake_identify,
                 sink=None, button=None, rate=100.0, solenoid=None, indicator=None):
        self.clock = ManualClock()
        self.solenoid = solenoid or Solenoid(17, max_on_time=MAX_ON, pin_factory=factory)
        self.rig = SimRig(TRUTH, theta0=0.25, clock=self.clock, duration=40.0)
        if hasattr(self.solenoid, "add_listener"):
            self.rig.attach(self.solenoid)
        self.sensor = SimulatedAngleSensor(self.rig.angle, self.clock, rate=rate, quantisation_bits=17)
        self.results: list = []  # the sink's measurements
        self.events: list = []
        self.config = config or SequencerConfig(capture_duration=4.0, identify_in_worker=False)
        self.seq = Sequencer(clock=self.clock, solenoid=self.solenoid, sensor=self.sensor, rig=RIG,
                             sink=sink if sink is not None else self.results.append, config=self.config,
                             identifier=identifier, button=button, indicator=indicator)
        self.seq.subscribe(self.events.append)

    def step(self, dt: float = 0.01) -> State:
        self.clock.advance(dt)
        return self.seq.poll()

    def run_until(self, predicate, max_steps: int = 20000, dt: float = 0.01) -> None:
        for _ in range(max_steps):
            if predicate():
                return
            self.step(dt)
        raise AssertionError(f"condition not reached; path so far {self.path()}")

    def run_to(self, state: State) -> None:
        self.run_until(lambda: self.seq.state is state)

    def path(self) -> list[str]:
        return [e.state.value for e in self.events]

    def close(self) -> None:
        self.seq.close()
        self.rig.close()
        if hasattr(self.solenoid, "close"):
            self.solenoid.close()


def on_durations(pin):
    """Durations (s, real time) of every on-interval recorded on a mock pin (active-high wiring)."""
    s = pin.states
    return [nxt.timestamp for cur, nxt in zip(s, s[1:]) if cur.state and not nxt.state]


def assert_solenoid_safe(h: Harness) -> None:
    """Off now, the pin's recorded history ends off, and no pulse outlasted the hard maximum."""
    assert not h.solenoid.is_active
    pin = h.solenoid.pin
    assert pin.state is False and pin.states[-1].state is False
    assert all(d <= MAX_ON + 0.25 for d in on_durations(pin))
