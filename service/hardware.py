"""Build the devices the sequencer drives from the configuration: real hardware or the simulated rig.

Simulated (``--sim`` or no ``[hardware]``): gpiozero mock pins for the
solenoid and the button, and a simulated pendulum that is held at its release
angle until the mock solenoid fires, then swings by the physics of
``[simulation]`` on a clock running ``time_scale`` times faster than real time.
The simulated pendulum is ``drivers.simrig.SimRig`` when that module is
installed; until then a thin adapter here couples the same pieces
(``measurement.Swing`` + ``drivers.SimulatedAngleSensor`` + the solenoid's
listener).
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from typing import Any, Callable

from drivers.backend import pin_factory
from drivers.button import PushButton
from drivers.clock import Clock, MonotonicClock, ScaledClock
from drivers.indicator import Indicator
from drivers.sensor import AngleSensor, SimulatedAngleSensor
from drivers.solenoid import Solenoid
from measurement import Pendulum, Swing

from .config import Config
from .errors import ConfigError

log = logging.getLogger("moi.hardware")

SIM_SOLENOID_PIN = 17
SIM_BUTTON_PIN = 27


@dataclass
class Devices:
    """What the sequencer gets; ``close()`` releases them (solenoid first: the safe state)."""

    clock: Clock
    solenoid: Solenoid
    sensor: AngleSensor
    button: PushButton | None = None
    indicator: Indicator | None = None
    simulated: bool = False
    sim: Any = None  # the simulated pendulum (tests read its truth)
    _closers: list[Callable[[], None]] = field(default_factory=list)

    def close(self) -> None:
        for obj in (self.solenoid, self.button, self.indicator, self.sensor):
            if obj is None:
                continue
            try:
                obj.close()
            except Exception:  # closing: keep releasing the others; the solenoid went first
                log.exception("closing %r failed", obj)
        for closer in self._closers:
            try:
                closer()
            except Exception:
                log.exception("closing the simulation failed")


class SimPendulum:
    """A pendulum held at theta0 until the solenoid fires, then swinging freely.

    angle(t): the true angle (rad) at clock time t (s). ``rearm()`` puts it
    back at theta0 and latched (the operator re-latching the arm).
    """

    def __init__(self, pendulum: Pendulum, theta0: float, clock: Clock, duration: float) -> None:
        self.pendulum = pendulum
        self.theta0 = float(theta0)
        self._clock = clock
        self._swing = Swing(pendulum, theta0, duration)
        self._lock = threading.Lock()
        self._released_at: float | None = None
        self.releases = 0

    def on_solenoid(self, active: bool) -> None:
        if active:
            with self._lock:
                if self._released_at is None:
                    self._released_at = self._clock.now()
                    self.releases += 1

    def rearm(self) -> None:
        with self._lock:
            self._released_at = None

    def angle(self, t: float) -> float:
        released = self._released_at
        if released is None or t <= released:
            return self.theta0
        return float(self._swing.angle(t - released))


class _RearmingSensor:
    """A simulated sensor whose ``start()`` re-latches the simulated pendulum first."""

    def __init__(self, inner: SimulatedAngleSensor, rig: SimPendulum) -> None:
        self._inner = inner
        self._rig = rig
        self.source = inner.source

    def start(self) -> None:
        self._rig.rearm()
        self._inner.start()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


def build_devices(config: Config) -> Devices:
    return _simulated(config) if config.simulated else _hardware(config)


def _simulated(config: Config) -> Devices:
    sim = config.simulation
    hw = config.hardware
    factory = pin_factory("mock")
    clock: Clock = ScaledClock(sim.time_scale) if sim.time_scale != 1.0 else MonotonicClock()
    sol_pin = hw.solenoid["pin"] if hw else SIM_SOLENOID_PIN
    btn_pin = hw.button["pin"] if hw and hw.button else SIM_BUTTON_PIN
    max_on = hw.solenoid["max_on_time"] if hw else 0.5
    solenoid = Solenoid(sol_pin, max_on_time=max_on, pin_factory=factory)
    button = None
    try:
        button = PushButton(btn_pin, pull_up=True, bounce_time=None, pin_factory=factory)
        pendulum = Pendulum(config.rig, sim.inertia, sim.effects)
        duration = config.sequencer.pre_trigger + config.sequencer.capture_duration + 5.0
        rig = SimPendulum(pendulum, sim.theta0, clock, duration)
        remove = solenoid.add_listener(rig.on_solenoid)
        inner = SimulatedAngleSensor(rig.angle, clock, rate=sim.rate, noise_std=sim.noise,
                                     quantisation_bits=sim.bits or None, seed=sim.seed, source="encoder")
        sensor = _RearmingSensor(inner, rig)
    except BaseException:
        solenoid.close()
        if button is not None:
            button.close()
        raise
    return Devices(clock=clock, solenoid=solenoid, sensor=sensor, button=button, simulated=True, sim=rig,
                   _closers=[remove])


def _hardware(config: Config) -> Devices:
    hw = config.hardware
    assert hw is not None
    factory = pin_factory(hw.gpio_backend)
    clock = MonotonicClock()
    opened: list[Any] = []
    try:
        s = hw.solenoid
        solenoid = Solenoid(s["pin"], active_high=s["active_high"], max_on_time=s["max_on_time"], pin_factory=factory)
        opened.append(solenoid)
        button = None
        if hw.button:
            b = hw.button
            button = PushButton(b["pin"], pull_up=b["pull_up"], bounce_time=b["bounce_time"], pin_factory=factory)
            opened.append(button)
        indicator = None
        if hw.indicator:
            i = hw.indicator
            indicator = Indicator(i["pin"], kind=i["kind"], active_high=i["active_high"], pin_factory=factory)
            opened.append(indicator)
        if hw.sensor == "encoder":
            try:
                from drivers.encoder import ModbusEncoder
            except ImportError:
                raise ConfigError("[hardware] sensor = \"encoder\": the encoder driver (drivers.encoder) is not "
                                  "available in this build") from None
            sensor = ModbusEncoder(clock=clock, **dict(hw.encoder or {}))
        else:  # guarded by the config schema
            raise ConfigError(f"[hardware] sensor {hw.sensor!r} is not supported")
    except BaseException:
        for obj in opened:
            obj.close()
        raise
    return Devices(clock=clock, solenoid=solenoid, sensor=sensor, button=button, indicator=indicator)
