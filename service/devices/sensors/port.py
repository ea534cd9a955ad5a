"""The sensor port: what the appliance knows of a kind of angle sensor.

A sensor kind (the Modbus encoder, the camera, the in-process simulated sensor) is one class with ``NAME`` (its
name in ``[hardware] sensor`` / ``[simulation] sensor``) and the class methods below: the driver built from its
settings, its settings table ``[hardware.<name>]`` (``service.settings.schema.SensorTable``: its keys, their docs
and defaults, the parse of the table), its simulated twin on the simulated rig, the health lines of `moi check`
and, for a camera, the camera file its frames are read with, where that file sits, how the file read again takes
effect and a frame now. ``service.settings.sensor_registry`` lists them: adding one is one module and one line
there. The configuration, the device builder, `moi check` and the web page hold a sensor kind and never name one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, ClassVar

from service.settings.schema import SensorFail, SensorTable

if TYPE_CHECKING:  # pragma: no cover
    from drivers.clock import Clock
    from drivers.sensor import AngleSensor
    from drivers.simrig import SimRig
    from service.settings.config import Config, SimulationSettings


class SensorKind:
    """The interface; a sensor kind subclasses it."""

    #: its name in the configuration
    NAME: ClassVar[str] = ""
    #: what the web page calls it (its set-up panel, the source of a one-off angle read)
    LABEL: ClassVar[str] = ""
    #: a device on the appliance ([hardware] sensor), or only a simulation ([simulation] sensor)
    HARDWARE: ClassVar[bool] = True
    #: the largest [simulation] time_scale its simulated twin keeps up with (None: any the simulation allows)
    MAX_TIME_SCALE: ClassVar[float | None] = None
    #: why the twin cannot go faster (said when time_scale is above MAX_TIME_SCALE)
    TIME_SCALE_REASON: ClassVar[str] = ""
    #: the groups whose devices it opens, and the device classes (``DeviceAllow=``, names as in /proc/devices):
    #: the systemd unit grants them (a test holds the unit to every sensor's)
    GROUPS: ClassVar[tuple[str, ...]] = ()
    DEVICE_CLASSES: ClassVar[tuple[str, ...]] = ()
    #: the time_scale of `moi measure --sim` with this sensor when none is given
    DEFAULT_TIME_SCALE: ClassVar[float] = 1.0
    #: its settings table ``[hardware.<NAME>]`` (None: a sensor without settings)
    TABLE: ClassVar[SensorTable | None] = None

    @classmethod
    def build(cls, config: Config, clock: Clock) -> AngleSensor:
        """The device's sensor from ``config.hardware`` (ConfigError / StartupError saying what is wrong)."""
        raise NotImplementedError

    @classmethod
    def simulation_values(cls, values: dict[str, Any], fail: SensorFail) -> None:
        """Completes the checked ``[simulation]`` values in place when it is the simulation's sensor (paths already
        resolved; the camera reads its camera file here, so a bad one is a configuration error)."""

    @classmethod
    def simulate(cls, sim: SimulationSettings, pendulum: SimRig, clock: Clock,
                 notes: list[str]) -> tuple[AngleSensor, list[Callable[[], None]]]:
        """Its simulated twin reading ``pendulum``, and what to stop after the sensor is closed (a simulated
        peer); one line per device built in ``notes``."""
        raise NotImplementedError

    @classmethod
    def health(cls, config: Config) -> list[tuple[str, bool, str]]:
        """`moi check`'s lines on the device: (what, ok, detail)."""
        return []

    @classmethod
    def camera_config(cls, config: Config) -> Any:
        """The camera file its frames are read with (``CameraConfig``), None when it gives no frames."""
        return None

    @classmethod
    def camera_file(cls, config: Config) -> str | None:
        """Where that camera file is (the file a new region of interest is written to); None when there is none
        to write (the demo camera, or a sensor without frames)."""
        return None

    @classmethod
    def use_camera(cls, config: Config, sensor: AngleSensor | None, camera: Any) -> Config:
        """A camera file read again (``CameraConfig``: a new region of interest) put to use: the running
        ``sensor`` (None: no devices yet) tracks with it from its next capture, and the configuration returned
        holds it. Main loop thread: the sensor is idle between captures there."""
        raise NotImplementedError(f"the {cls.NAME} sensor reads no camera file")

    @classmethod
    def frame(cls, sensor: AngleSensor) -> Any:
        """One frame of the running ``sensor`` now (an image; None: a sensor without frames). Main loop thread,
        never during a capture."""
        return None
