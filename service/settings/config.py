"""The validated configuration's types: one settings dataclass per table of the appliance's own (its fields are
the table's keys and defaults) and ``Config``, the whole of it.

The assembler (``service.config.appliance``) builds them from the file; the devices, the sensors and the
publisher port read them. Each publisher's and sensor's own settings are declared in its module; ``Config`` and
``HardwareSettings`` name each one registered (``Config.modbus``, ``HardwareSettings.camera``...).
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from firmware_host import SequencerConfig
from measurement import Options, Rig
from measurement.errors import InvalidInput
from service.settings import sensor_registry
from service.settings.defaults import DEMO_EFFECTS, DEMO_INERTIA, DEMO_THETA0


# --- the settings: each table of the file is one dataclass; its fields are the table's keys and defaults ----
@dataclass(frozen=True)
class DeviceSettings:
    """``[device]``: the device id (an MQTT topic level), the store, the rig file, logging."""

    id: str = "moi"
    state_dir: str | None = None
    rig: str | None = None
    log_level: str = "info"
    store_trace: bool = True
    require_calibration: bool = False


@dataclass(frozen=True)
class SimulationSettings:
    """``[simulation]``: the simulated rig (SI units; see ``SCHEMA["simulation"]`` for each key)."""

    inertia: float = DEMO_INERTIA
    effects: Mapping[str, Mapping[str, float]] = field(default_factory=lambda: copy.deepcopy(DEMO_EFFECTS))
    theta0: float = DEMO_THETA0
    rate: float = 200.0
    noise: float = 1e-4
    bits: int = 17
    time_scale: float = 1.0
    seed: int | None = None
    sensor: str = "encoder"
    latency: float = 0.0002
    camera: str | None = None        # camera file (resolved), None: the demo camera
    camera_yaw_deg: float = 0.0
    camera_config: Any = None        # the parsed camera file (CameraConfig) with sensor = "camera"
    drop_rate: float = 0.0
    crc_rate: float = 0.0
    glitch_rate: float = 0.0

    def __post_init__(self) -> None:
        ts = self.time_scale
        if not (isinstance(ts, (int, float)) and not isinstance(ts, bool) and 0 < ts <= MAX_TIME_SCALE):
            raise InvalidInput(f"time_scale must be in (0, {MAX_TIME_SCALE:g}] simulated s per wall-clock s, got {ts!r}")
        kind = sensor_registry.sensor(self.sensor) if self.sensor in sensor_registry.names() else None
        if kind is not None and kind.MAX_TIME_SCALE is not None and ts > kind.MAX_TIME_SCALE:
            raise InvalidInput(f"time_scale {ts:g} is above {kind.MAX_TIME_SCALE:g}, {kind.TIME_SCALE_REASON} "
                               f"(use time_scale <= {kind.MAX_TIME_SCALE:g})")


#: largest [simulation] time_scale: simulated seconds per wall-clock second
MAX_TIME_SCALE = 1000.0



@dataclass(frozen=True)
class RecipeSettings:
    """``[recipes]``: the recipe directory (one TOML file per part type) and the recipe active at start."""

    directory: str | None = None
    active: str | None = None


@dataclass(frozen=True, kw_only=True)
class HardwareSettings:
    """``[hardware]``: the GPIO backend, the angle sensor and the device tables (checked by the drivers' settings).

    sensors: the chosen sensor's settings by its name, parsed from its table ``[hardware.<sensor>]`` by its
    sensor module (``SensorKind.TABLE``); ``hardware.<name>`` reads them (None for another sensor).
    """

    gpio_backend: str | None = None
    sensor: str = "encoder"
    solenoid: Mapping[str, Any]
    button: Mapping[str, Any] | None = None
    indicator: Mapping[str, Any] | None = None
    sensors: Mapping[str, Any] = field(default_factory=dict)

    # one property per hardware sensor of the registry (a test holds the two together): the chosen sensor's
    # settings, None for another; a sensor added to the registry is read as ``sensors[<name>]`` until it has one
    @property
    def encoder(self) -> Any:
        """``[hardware.encoder]`` parsed by the encoder's sensor module (``drivers.encoder.EncoderConfig`` values)."""
        return self.sensors.get("encoder")

    @property
    def camera(self) -> Any:
        """``[hardware.camera]`` parsed by the camera's sensor module (``CameraSettings``)."""
        return self.sensors.get("camera")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the tables as the file has them, one key per hardware sensor (null: not the chosen one)."""
        d = dataclasses.asdict(self)
        chosen = d.pop("sensors")
        return {**d, **{name: chosen.get(name) for name in sensor_registry.names(hardware=True)}}


# --- the validated configuration ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Config:
    """The whole validated configuration (SI units)."""

    source: str                      # the file it came from ("<defaults>" when none)
    device_id: str
    state_dir: Path
    log_level: str
    store_trace: bool
    rig: Rig
    rig_path: str | None
    simulated: bool
    simulation: SimulationSettings
    hardware: HardwareSettings | None
    sequencer: SequencerConfig
    identification: Options
    #: each registered publisher's settings by its table's name (``config.mqtt``...); None: that publisher is off
    publishers: Mapping[str, Any] = field(default_factory=dict)
    recipes: Any = None              # service.parts.recipes.RecipeBook (every recipe of [recipes] directory, checked)
    active_recipe: str | None = None  # [recipes] active
    require_calibration: bool = False  # [device] require_calibration: a rig without a calibration record refuses

    # one property per publisher of the registry (a test holds the two together): its settings, None when off; a
    # publisher added to the registry is read as ``publishers[<name>]`` until it has one
    @property
    def modbus(self) -> Any:
        """``[modbus]`` (``ModbusSettings``), None when off."""
        return self.publishers.get("modbus")

    @property
    def web(self) -> Any:
        """``[web]`` (``WebSettings``), None when off."""
        return self.publishers.get("web")

    @property
    def mqtt(self) -> Any:
        """``[mqtt]`` (``MqttSettings``), None when off."""
        return self.publishers.get("mqtt")

    @property
    def opcua(self) -> Any:
        """``[opcua]`` (``OpcUaSettings``), None when off."""
        return self.publishers.get("opcua")

    @property
    def sparkplug(self) -> Any:
        """``[sparkplug]`` (``SparkplugSettings``), None when off."""
        return self.publishers.get("sparkplug")

    def with_publisher(self, name: str, settings: Any) -> Config:
        """This configuration with the settings of publisher ``name`` replaced (None: off)."""
        return dataclasses.replace(self, publishers={**self.publishers, name: settings})

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary of what the daemon runs with (passwords left out)."""
        def clean(obj: Any) -> Any:
            if obj is None:
                return None
            d = dataclasses.asdict(obj)
            for secret in ("password",):
                if d.get(secret):
                    d[secret] = "***"
            return d
        return {
            "source": self.source, "device_id": self.device_id, "state_dir": str(self.state_dir),
            "require_calibration": self.require_calibration,
            "rig_path": self.rig_path, "rig": self.rig.to_dict(), "simulated": self.simulated,
            "simulation": clean(self.simulation) if self.simulated else None,
            "hardware": None if self.hardware is None else self.hardware.to_dict(), "sequencer": clean(self.sequencer),
            "identification": clean(self.identification),
            "recipes": None if self.recipes is None else {
                "directory": self.recipes.directory, "active": self.active_recipe,
                "recipes": [{"name": r.name, "number": r.number, "version": r.version, "path": r.path}
                            for r in self.recipes.recipes]},
            **{name: clean(settings) for name, settings in self.publishers.items()},
        }
