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
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Callable

from drivers.backend import pin_factory
from drivers.button import PushButton
from drivers.clock import Clock, MonotonicClock, ScaledClock
from drivers.errors import DriverConfigError
from drivers.indicator import Indicator
from drivers.sensor import AngleSensor, SimulatedAngleSensor
from drivers.settings import SolenoidSettings
from drivers.simrig import MAX_DURATION as SIM_MAX_DURATION, SimRig
from drivers.solenoid import Solenoid
from firmware_host import SequencerConfig
from measurement import Pendulum, Rig

from service.config.appliance import Config, HardwareSettings, SimulationSettings
from .defaults import SIM_BUTTON_PIN, SIM_SOLENOID_PIN, demo_camera
from service.errors import ConfigError, StartupError

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


#: the simulated encoder client's reply time-out, s of real time (a scaled clock must not stretch it)
SIM_ENCODER_TIMEOUT = 0.05


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
        if sim.sensor == "encoder":
            from drivers.encoder import ModbusEncoder
            from drivers.sim_encoder import SimEncoderConfig, SimEncoderServer

            bits = sim.bits or 17
            server = SimEncoderServer(pendulum.angle, clock, SimEncoderConfig(
                counts_per_turn=1 << bits, registers=1 if bits <= 16 else 2, noise_std=sim.noise,
                latency=sim.latency, drop_rate=sim.drop_rate, crc_error_rate=sim.crc_rate, glitch_rate=sim.glitch_rate,
                seed=sim.seed)).start()
            opened.append(server.stop)
            closers.insert(0, server.stop)
            notes.append(f"simulated encoder: Modbus RTU on {server.url}, {bits} bits")
            if sim.time_scale > 1.0:
                # the round trip's jitter (tens of µs of wall time) is time_scale× longer on the simulated clock
                log.warning("simulated encoder at time_scale %g: the timestamps jitter %g× more in simulated time "
                            "than in real time; expect correlated_residual or outlier flags a real-time capture "
                            "would not raise (the default time_scale 1 keeps up)", sim.time_scale, sim.time_scale)
            # requests paced at `rate` (simulated time), as a device's client would be: back to back the
            # simulated link answers some 2000 reads/s and loads the host that dates them
            inner: Any = ModbusEncoder(server.encoder_config(
                timeout=SIM_ENCODER_TIMEOUT, min_interval=min(1.0 / (sim.rate * sim.time_scale), 1.0)), clock)
        elif sim.sensor == "camera":
            inner = _simulated_camera(sim, pendulum, clock, notes)
            opened.append(inner.close)
        else:
            inner = SimulatedAngleSensor(pendulum.angle, clock, rate=sim.rate, noise_std=sim.noise,
                                         quantisation_bits=sim.bits or None, seed=sim.seed, source="encoder")
            notes.append(f"simulated sensor: in process at {sim.rate:g} Hz")
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
        if hw.sensor == "encoder":
            from drivers.encoder import EncoderConfig, ModbusEncoder

            try:
                enc = EncoderConfig.from_dict(dict(hw.encoder or {}))
            except DriverConfigError as exc:
                raise ConfigError(f"{config.source}: [hardware.encoder]: {exc}") from None
            sensor = ModbusEncoder(enc, clock)
        elif hw.sensor == "camera":
            sensor = _camera(config, clock)
        else:  # guarded by the config schema
            raise ConfigError(f"[hardware] sensor {hw.sensor!r} is not supported")
    except BaseException:
        for obj in opened:
            obj.close()
        raise
    return Devices(clock=clock, solenoid=solenoid, sensor=sensor, button=button, indicator=indicator)


def _simulated_camera(sim: SimulationSettings, rig: SimRig, clock: Clock, notes: list[str]) -> Any:
    """A mock camera filming the simulated rig (yawed by ``camera_yaw_deg``) and the device's camera sensor on it."""
    from drivers.camera import open_camera
    from drivers.camera_sensor import CameraAngleSensor
    from measurement.vision.render import CameraPose

    cfg = sim.camera_config
    if cfg is None:  # SimulationSettings built by hand rather than by parse_config, which reads the file
        from service.config.camera import read_camera
        cfg = read_camera(sim.camera) if sim.camera else demo_camera()
    if sim.time_scale != 1.0:
        # frames are rendered on the main loop's thread (~5 ms each at 640×480); faster than real time,
        # more frames fall due between two polls than the mock's 8-frame buffer holds: the rest are dropped
        log.warning("simulated camera at time_scale %g: %g frames/s of swing to render per real second; "
                    "expect dropped_frames (use time_scale = 1 with the camera)", sim.time_scale,
                    cfg.camera.fps * sim.time_scale)
    camera = open_camera(cfg, angle_source=rig.angle, clock=clock,
                         pose=CameraPose(yaw=math.radians(sim.camera_yaw_deg)), drop_probability=sim.drop_rate,
                         seed=sim.seed)
    try:
        sensor = CameraAngleSensor(camera, cfg, clock)
    except BaseException:
        camera.close()
        raise
    cam = cfg.camera
    seen = (f"marker radius {cfg.cylinder.radius:g} m at {cfg.cylinder.distance:g} m" if cfg.edge
            else f"{cfg.target.kind} target, {cfg.target.view}")
    notes.append(f"simulated camera: {cam.width}×{cam.height} px at {cam.fps:g} frames/s, yaw {sim.camera_yaw_deg:g}°, "
                 f"{seen}")
    return sensor


def _camera(config: Config, clock: Clock) -> Any:
    """The V4L2 camera of ``[hardware.camera]`` as the angle sensor.

    The camera file was read and checked with the configuration; a device that is missing,
    busy or cannot deliver the file's resolution is a ``StartupError`` (exit 3, systemd
    restarts the daemon: a USB camera may still be enumerating) naming the setting.
    """
    from drivers.camera import open_camera
    from drivers.camera_sensor import CameraAngleSensor

    hw = config.hardware
    assert hw is not None and hw.camera is not None, "guarded by the config: sensor = camera needs [hardware.camera]"
    settings = hw.camera
    try:
        camera = open_camera(settings.config, settings.device)
    except DriverConfigError as exc:
        raise StartupError(f"{config.source}: [hardware.camera] device: {exc}") from None
    try:
        sensor = CameraAngleSensor(camera, settings.config, clock, max_lost_time=settings.max_lost_time)
    except DriverConfigError as exc:
        camera.close()
        raise ConfigError(f"{config.source}: [hardware.camera]: {exc}") from None
    except BaseException:
        camera.close()
        raise
    cam = settings.config.camera
    log.info("camera %s: %d×%d px at %g frames/s (camera file %s)", settings.device, cam.width, cam.height, cam.fps,
             settings.file)
    return sensor
