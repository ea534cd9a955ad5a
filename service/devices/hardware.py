"""Build the devices the sequencer drives from the configuration: real hardware or the simulated rig.

Simulated (``--sim`` or no ``[hardware]``): gpiozero mock pins for the
solenoid and the button, and ``drivers.simrig.SimRig``: a pendulum held at its
release angle until the mock solenoid fires, then swinging by the physics of
``[simulation]`` on a clock running ``time_scale`` times faster than real
time. With ``[simulation] sensor = "encoder"`` (the default) it is read over a
real Modbus RTU link: ``drivers.sim_encoder.SimEncoderServer`` on a loopback
socket and the same ``drivers.encoder.ModbusEncoder`` the device uses; with
``"direct"`` an in-process ``drivers.SimulatedAngleSensor`` samples it at
``rate`` (faster, for tests); with ``"camera"`` a ``drivers.camera.MockCamera``
renders the marker at the rig's angle (yawed by ``camera_yaw_deg``) and the
same ``drivers.camera_sensor.CameraAngleSensor`` the device uses tracks it and
fits the yaw in its ``finish`` hook.

Hardware: the Modbus encoder of ``[hardware.encoder]``, or the V4L2 camera of
``[hardware.camera]`` through ``CameraAngleSensor``.

Each sensor, its driver and its simulated twin, is one module of ``service.devices.sensors`` (the
sensor port); this builder asks the registry for the one the configuration names.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable

from drivers.backend import pin_factory
from drivers.button import PushButton
from drivers.clock import Clock, MonotonicClock, ScaledClock
from drivers.indicator import Indicator
from drivers.sensor import AngleSensor
from drivers.settings import SolenoidSettings
from drivers.simrig import MAX_DURATION as SIM_MAX_DURATION
from drivers.simrig import SimRig
from drivers.solenoid import Solenoid
from firmware_host import SequencerConfig
from measurement import Pendulum, Rig
from service.settings import sensor_registry as sensors
from service.settings.config import Config, HardwareSettings, SimulationSettings
from service.settings.defaults import SIM_BUTTON_PIN, SIM_SOLENOID_PIN

log = logging.getLogger("moi.hardware")


@dataclass
class Devices:
    """What the sequencer gets; ``close()`` releases them (solenoid first: the safe state)."""

    clock: Clock
    solenoid: Solenoid
    sensor: AngleSensor
    button: PushButton | None = None
    indicator: Indicator | None = None
    simulated: bool = False
    sim: Any = None  # the SimRig (tests read its truth)
    notes: list[str] = field(default_factory=list)  # what was built, one line per device (printed by `moi measure`)
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

    def __enter__(self) -> "Devices":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class _RelatchingSensor:
    """A sensor on the simulated rig whose ``start()`` first re-latches the pendulum at θ0
    (what the operator does between two measurements).

    Everything else is the inner sensor's, looked up on it: ``read``, ``stop``, ``stats``,
    ``flags``, ``close`` and, when the inner sensor has one, the sequencer's optional
    ``finish(trace)`` hook (the camera's yaw fit); a sensor without it has none here either,
    so the sequencer's ``getattr(sensor, "finish", None)`` sees the truth.
    """

    def __init__(self, inner: Any, rig: SimRig) -> None:
        self._inner = inner
        self._rig = rig
        self.source = inner.source

    def start(self) -> None:
        self._rig.relatch()
        self._inner.start()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


def build_devices(config: Config) -> Devices:
    """The devices of ``config``: the simulated rig (``[simulation]``) or the hardware of ``[hardware]``."""
    if config.simulated:
        return build_simulated(config.rig, config.simulation, config.sequencer, config.hardware)
    return _hardware(config)


def build_simulated(rig: Rig, sim: SimulationSettings, sequencer: SequencerConfig,
                    hardware: HardwareSettings | None = None) -> Devices:
    """The simulated appliance: mock pins, the simulated pendulum and the angle sensor of ``sim.sensor``.

    The one builder of the simulated rig, for `moi run` without hardware (or ``--sim``) and for
    `moi measure --sim`. rig: the rig the pendulum swings on; sim: the simulated part, its damping,
    the sensor and its imperfections; sequencer: how long a capture may last (the simulation runs
    that long); hardware: when given (``--sim`` with a ``[hardware]`` table), its solenoid and button
    pins and the solenoid's maximum on-time are used on the mock pins. ``Devices.notes`` says what
    was built, one line per device.
    """
    factory = pin_factory("mock")
    clock: Clock = ScaledClock(sim.time_scale) if sim.time_scale != 1.0 else MonotonicClock()
    sol = SolenoidSettings(SIM_SOLENOID_PIN) if hardware is None else SolenoidSettings(**hardware.solenoid)
    btn_pin = hardware.button["pin"] if hardware and hardware.button else SIM_BUTTON_PIN
    notes: list[str] = []
    opened: list[Callable[[], None]] = []
    solenoid = Solenoid(sol.pin, max_on_time=sol.max_on_time, pin_factory=factory)
    opened.append(solenoid.close)
    try:
        button = PushButton(btn_pin, pull_up=True, bounce_time=None, pin_factory=factory)
        opened.append(button.close)
        duration = min(sequencer.pre_trigger + sequencer.capture_duration + 5.0, SIM_MAX_DURATION)
        pendulum = SimRig(Pendulum(rig, sim.inertia, sim.effects), theta0=sim.theta0, clock=clock,
                          duration=duration).attach(solenoid)
        closers: list[Callable[[], None]] = [pendulum.close]
        opened.append(pendulum.close)
        inner, stops = sensors.sensor(sim.sensor).simulate(sim, pendulum, clock, notes)
        opened.append(inner.close)
        closers[:0] = stops
        opened += stops
        sensor = _RelatchingSensor(inner, pendulum)
    except BaseException:
        for close in reversed(opened):
            close()
        raise
    for line in notes:
        log.info("%s", line)
    return Devices(clock=clock, solenoid=solenoid, sensor=sensor, button=button, simulated=True, sim=pendulum,
                   notes=notes, _closers=closers)


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
        sensor = sensors.sensor(hw.sensor).build(config, clock)
    except BaseException:
        for obj in opened:
            obj.close()
        raise
    return Devices(clock=clock, solenoid=solenoid, sensor=sensor, button=button, indicator=indicator)
