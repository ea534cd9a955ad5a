"""The angle sensors the appliance knows: adding one is one module and one line here.

Each entry names the sensor's configuration name and the module of its ``SENSOR`` class (the port,
``service.devices.sensors.port``), imported when the configuration reads the sensors' settings tables
(``SensorKind.TABLE``, no driver imported there) and when a sensor is built, checked or shown.

It stands on the configuration's floor because the configuration's types read it (a simulated sensor's
time-scale limit, the hardware sensors' names): it names the sensor modules and imports one only when asked.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class SensorEntry:
    """One sensor kind: its name, the module of its ``SENSOR`` class, and whether it is a device on the appliance
    (``[hardware] sensor``) as well as a simulation (``[simulation] sensor``)."""

    name: str
    module: str
    hardware: bool = True

    def load(self) -> Any:
        """The sensor kind (``service.devices.sensors.port.SensorKind``)."""
        return importlib.import_module(self.module).SENSOR

    def table(self) -> Any:
        """Its settings table ``[hardware.<name>]`` (``service.devices.sensors.port.SensorTable``; None: none)."""
        return self.load().TABLE


SENSORS: tuple[SensorEntry, ...] = (
    SensorEntry("encoder", "service.devices.sensors.encoder"),
    SensorEntry("direct", "service.devices.sensors.direct", hardware=False),
    SensorEntry("camera", "service.devices.sensors.camera"),
)


def names(*, hardware: bool = False) -> tuple[str, ...]:
    """The sensors' names (``hardware``: only those that are devices on the appliance)."""
    return tuple(e.name for e in SENSORS if e.hardware or not hardware)


def sensor(name: str) -> Any:
    """The sensor kind called ``name`` (ValueError naming the known ones)."""
    for e in SENSORS:
        if e.name == name:
            return e.load()
    raise ValueError(f"no angle sensor {name!r}; expected one of {', '.join(names())}")


def running(config: Any) -> Any:
    """The sensor kind ``config`` reads: ``[simulation] sensor`` when simulated, else ``[hardware] sensor``."""
    return sensor(config.simulation.sensor if config.simulated or config.hardware is None else config.hardware.sensor)
