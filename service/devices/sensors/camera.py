"""The camera (``[hardware.camera]``: a V4L2 device and its camera file, read by
``drivers.camera_sensor.CameraAngleSensor``), and its simulated twin: ``drivers.camera.MockCamera`` rendering the
marker at the simulated rig's angle (yawed by ``camera_yaw_deg``), read by the same camera sensor, which fits
the yaw in its ``finish`` hook."""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from drivers.errors import DriverConfigError
from service.errors import ConfigError, StartupError

from .port import SensorKind

if TYPE_CHECKING:  # pragma: no cover
    from drivers.clock import Clock
    from drivers.simrig import SimRig
    from service.config.appliance import Config, SimulationSettings

log = logging.getLogger("moi.hardware")


class Camera(SensorKind):
    NAME = "camera"
    LABEL = "camera"
    DEFAULT_TIME_SCALE = 1.0  # the mock camera renders its frames in real time
    GROUPS = ("video",)
    DEVICE_CLASSES = ("char-video4linux", "char-media")

    @classmethod
    def build(cls, config: Config, clock: Clock) -> Any:
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
        log.info("camera %s: %d×%d px at %g frames/s (camera file %s)", settings.device, cam.width, cam.height,
                 cam.fps, settings.file)
        return sensor

    @classmethod
    def simulate(cls, sim: SimulationSettings, pendulum: SimRig, clock: Clock,
                 notes: list[str]) -> tuple[Any, list[Callable[[], None]]]:
        """A mock camera filming the simulated rig (yawed by ``camera_yaw_deg``) and the device's camera sensor
        on it."""
        from drivers.camera import open_camera
        from drivers.camera_sensor import CameraAngleSensor
        from measurement.vision.render import CameraPose

        cfg = cls._simulated_config(sim)
        if sim.time_scale != 1.0:
            # frames are rendered on the main loop's thread (~5 ms each at 640×480); faster than real time,
            # more frames fall due between two polls than the mock's 8-frame buffer holds: the rest are dropped
            log.warning("simulated camera at time_scale %g: %g frames/s of swing to render per real second; "
                        "expect dropped_frames (use time_scale = 1 with the camera)", sim.time_scale,
                        cfg.camera.fps * sim.time_scale)
        camera = open_camera(cfg, angle_source=pendulum.angle, clock=clock,
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
        notes.append(f"simulated camera: {cam.width}×{cam.height} px at {cam.fps:g} frames/s, yaw "
                     f"{sim.camera_yaw_deg:g}°, {seen}")
        return sensor, []

    @staticmethod
    def _simulated_config(sim: SimulationSettings) -> Any:
        cfg = sim.camera_config
        if cfg is None:  # SimulationSettings built by hand rather than by parse_config, which reads the file
            from service.config.camera import read_camera
            from service.devices.defaults import demo_camera
            cfg = read_camera(sim.camera) if sim.camera else demo_camera()
        return cfg

    @classmethod
    def health(cls, config: Config) -> list[tuple[str, bool, str]]:
        hw = config.hardware
        if hw is None or hw.camera is None:
            return []
        dev = hw.camera.device
        path = Path(f"/dev/video{dev}") if isinstance(dev, int) else Path(str(dev))
        return [("camera", path.exists(), f"{path}" + (" present" if path.exists() else " does not exist"))]

    @classmethod
    def camera_config(cls, config: Config) -> Any:
        if config.simulated:
            return config.simulation.camera_config
        return config.hardware.camera.config if config.hardware is not None and config.hardware.camera else None


SENSOR = Camera
