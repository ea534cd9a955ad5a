"""The camera (``[hardware.camera]``: a V4L2 device and its camera file, read by
``drivers.camera_sensor.CameraAngleSensor``), and its simulated twin: ``drivers.camera.MockCamera`` rendering the
marker at the simulated rig's angle (yawed by ``camera_yaw_deg``), read by the same camera sensor, which fits
the yaw in its ``finish`` hook.

The camera file sits in ``[hardware.camera] file`` (``[simulation] camera`` when simulated; none: the demo camera),
parsed with the configuration (``camera_config``). The set-up page writes a new region of interest to it
(``camera_file``) and puts the file read again to use (``use_camera``): the running sensor tracks with it from its
next capture, the running configuration holds it."""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from drivers.errors import DriverConfigError
from measurement.errors import InvalidInput
from service.errors import ConfigError, StartupError
from service.settings.schema import SensorFail, SensorTable, doc

from .port import SensorKind

if TYPE_CHECKING:  # pragma: no cover
    from drivers.clock import Clock
    from drivers.simrig import SimRig
    from service.settings.config import Config, SimulationSettings

log = logging.getLogger("moi.hardware")


@dataclass(frozen=True)
class CameraSettings:
    """``[hardware.camera]``: the V4L2 device, the camera file (path and parsed content), the lost-marker limit."""

    device: str | int
    file: str
    max_lost_time: float = 0.5
    config: Any = None  # measurement.vision.CameraConfig (imported lazily: it loads OpenCV)


def read_camera_file(path: str | None, key: str, fail: SensorFail) -> Any:
    """The camera file at ``path`` (None: the demo camera) as a ``CameraConfig``; a missing or malformed file is
    a one-line error naming the configuration file, the key and the camera file."""
    from service.settings.defaults import demo_camera
    from service.sources.camera import read_camera

    if path is None:
        return demo_camera()
    try:
        return read_camera(path)
    except InvalidInput as exc:  # InputFileError (not found, not TOML) or VisionError (naming the file)
        raise fail(key, str(exc)) from None


def _parse(values: dict[str, Any], fail: SensorFail) -> CameraSettings:
    return CameraSettings(**values, config=read_camera_file(values["file"], "file", fail))


class Camera(SensorKind):
    NAME = "camera"
    LABEL = "camera"
    DEFAULT_TIME_SCALE = 1.0  # the mock camera renders its frames in real time
    GROUPS = ("video",)
    DEVICE_CLASSES = ("char-video4linux", "char-media")
    TABLE = SensorTable(
        what="a camera", doc="[hardware.camera] device, file, max_lost_time (required with sensor = \"camera\")",
        needs="device = \"/dev/video0\", file = the camera file", settings=CameraSettings, keys={
            "device": doc("V4L2 capture device: a path like \"/dev/video0\" (better: a stable /dev/v4l/by-id/... "
                          "link) or an index", kind="videodevice"),
            "file": doc("camera file: intrinsics, resolution and fps, marker radius and distance, optional [pose] "
                        "(docs/vision.md); relative to this file", kind="path"),
            "max_lost_time": doc("no marker in the frames (lost or corrupt) for this long in a row → FAULT, s "
                                 "(at least 5 frames)", min=0, min_open=True),
        }, parse=_parse)

    @classmethod
    def build(cls, config: Config, clock: Clock) -> Any:
        """The V4L2 camera of ``[hardware.camera]`` as the angle sensor.

        The camera file was read and checked with the configuration; a device that is missing,
        busy or cannot deliver the file's resolution is a ``StartupError`` (exit 3, systemd
        restarts the daemon: a USB camera may still be enumerating) naming the setting.
        """
        from drivers.camera import open_camera
        from drivers.camera_sensor import CameraAngleSensor

        settings = cls._settings(config)
        assert settings is not None, "guarded by the config: sensor = camera needs [hardware.camera]"
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
    def _settings(cls, config: Config) -> CameraSettings | None:
        return None if config.hardware is None else config.hardware.sensors.get(cls.NAME)

    @classmethod
    def simulation_values(cls, values: dict[str, Any], fail: SensorFail) -> None:
        values["camera_config"] = read_camera_file(values["camera"], "camera", fail)

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
                        cfg.camera.frame_rate("the simulated camera") * sim.time_scale)
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
            from service.settings.defaults import demo_camera
            from service.sources.camera import read_camera
            cfg = read_camera(sim.camera) if sim.camera else demo_camera()
        return cfg

    @classmethod
    def health(cls, config: Config) -> list[tuple[str, bool, str]]:
        settings = cls._settings(config)
        if settings is None:
            return []
        dev = settings.device
        path = Path(f"/dev/video{dev}") if isinstance(dev, int) else Path(str(dev))
        return [("camera", path.exists(), f"{path}" + (" present" if path.exists() else " does not exist"))]

    # --- the camera file: where it sits in the configuration, and how a file read again takes effect ---------
    @classmethod
    def camera_config(cls, config: Config) -> Any:
        if config.simulated:
            return config.simulation.camera_config
        settings = cls._settings(config)
        return None if settings is None else settings.config

    @classmethod
    def camera_file(cls, config: Config) -> str | None:
        """``[simulation] camera`` when simulated (None: the demo camera), else ``[hardware.camera] file``."""
        if config.simulated:
            return config.simulation.camera
        settings = cls._settings(config)
        return None if settings is None else settings.file

    @classmethod
    def use_camera(cls, config: Config, sensor: Any, camera: Any) -> Config:
        """The camera sensor (``CameraAngleSensor``, its frame size checked) builds its next capture's tracker
        from ``camera``; the configuration returned holds it where ``camera_config`` reads it."""
        if sensor is not None:
            sensor.use_camera_file(camera)
        if config.simulated:
            return dataclasses.replace(config, simulation=dataclasses.replace(config.simulation, camera_config=camera))
        settings = cls._settings(config)
        assert config.hardware is not None and settings is not None, "guarded by camera_file: a camera file to use"
        sensors = {**config.hardware.sensors, cls.NAME: dataclasses.replace(settings, config=camera)}
        return dataclasses.replace(config, hardware=dataclasses.replace(config.hardware, sensors=sensors))

    @classmethod
    def frame(cls, sensor: Any) -> Any:
        return sensor.camera.grab().image


SENSOR = Camera
