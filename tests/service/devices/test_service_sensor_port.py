"""A sensor is one module registered in one place: the configuration (its settings table), the device builder,
`moi check` and the web page hold a sensor kind and name none."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from drivers.sensor import SimulatedAngleSensor
from firmware_host import SequencerConfig
from measurement.errors import InvalidInput
from service.config.appliance import load_config, parse_config, reference_markdown
from service.config.check import check_config
from service.devices.hardware import build_devices, build_simulated
from service.devices.sensors.port import SensorKind
from service.errors import ConfigError
from service.settings import sensor_registry as registry
from service.settings.config import SimulationSettings
from service.settings.schema import SensorTable
from service.settings.sensor_registry import SensorEntry


@dataclasses.dataclass(frozen=True)
class DummySettings:
    """``[hardware.dummy]``: the inclinometer's I2C bus and address."""

    bus: str
    address: int = 0x68


def _parse(values, fail) -> DummySettings:
    if not values["bus"].startswith("/dev/i2c-"):
        raise fail("bus", f"expected an I2C bus like \"/dev/i2c-1\", got {values['bus']!r}")
    return DummySettings(**values)


class DummySensor(SensorKind):
    """An inclinometer read in process: its settings table, the driver, its simulated twin and its health."""

    NAME = "dummy"
    LABEL = "inclinometer"
    MAX_TIME_SCALE = 5.0
    TIME_SCALE_REASON = "the dummy's bus is slow"
    TABLE = SensorTable(what="an I2C inclinometer", doc="[hardware.dummy] bus, address",
                        needs="bus = \"/dev/i2c-1\"", settings=DummySettings,
                        keys={"bus": dict(doc="the inclinometer's I2C bus"),
                              "address": dict(doc="its I2C address", min=0, max=127)}, parse=_parse)
    built: list[str] = []

    @classmethod
    def build(cls, config, clock):
        cls.built.append(f"device on {config.hardware.sensors['dummy'].bus}")
        return SimulatedAngleSensor(lambda t: 0.1, clock, rate=100.0, source="inclinometer")

    @classmethod
    def simulate(cls, sim, pendulum, clock, notes):
        cls.built.append("twin")
        notes.append("simulated dummy inclinometer")
        return (SimulatedAngleSensor(pendulum.angle, clock, rate=sim.rate, source="inclinometer"),
                [lambda: cls.built.append("bus stopped")])

    @classmethod
    def health(cls, config):
        return [("inclinometer bus", False, f"{config.hardware.sensors['dummy'].bus} does not exist")]


SENSOR = DummySensor


@pytest.fixture
def registered(monkeypatch):
    """The one line that adds the dummy sensor: its entry in the registry (this module is its sensor module)."""
    monkeypatch.setattr(registry, "SENSORS", (*registry.SENSORS, SensorEntry("dummy", __name__)))
    DummySensor.built.clear()


def test_the_registered_sensors_are_modules_of_the_port():
    for entry in registry.SENSORS:
        kind = entry.load()
        assert issubclass(kind, SensorKind) and entry.name == kind.NAME and entry.hardware == kind.HARDWARE
    assert registry.names(hardware=True) == ("encoder", "camera")
    with pytest.raises(ValueError, match="no angle sensor 'imu'; expected one of encoder, direct, camera"):
        registry.sensor("imu")


def test_every_hardware_sensor_of_the_registry_is_named_by_the_hardware_settings():
    """``HardwareSettings.<name>`` is written out (readers and mypy see it): one per hardware sensor."""
    from service.settings.config import HardwareSettings

    for name in registry.names(hardware=True):
        assert isinstance(getattr(HardwareSettings, name, None), property), f"HardwareSettings.{name}"
    hw = HardwareSettings(solenoid={"pin": 17}, sensors={"encoder": {"port": "/dev/ttyUSB0"}})
    assert hw.encoder == {"port": "/dev/ttyUSB0"} and hw.camera is None


def test_a_dummy_sensor_registered_in_one_place_is_the_simulated_rigs_sensor(registered):
    sim = SimulationSettings(sensor="dummy", time_scale=2.0)
    devices = build_simulated(parse_config({}).rig, sim, SequencerConfig())
    try:
        assert DummySensor.built == ["twin"] and devices.notes[-1] == "simulated dummy inclinometer"
        assert devices.sensor.source == "inclinometer"
    finally:
        devices.close()
    assert DummySensor.built[-1] == "bus stopped", "the twin's peer is stopped with the devices"
    with pytest.raises(InvalidInput, match=r"time_scale 6 is above 5, the dummy's bus is slow \(use time_scale <= 5\)"):
        SimulationSettings(sensor="dummy", time_scale=6.0)


def _dummy_config(tmp_path: Path, dummy: str | None = 'bus = "/dev/i2c-3"\n') -> Path:
    """A configuration file with sensor = "dummy" (and [hardware.dummy] holding ``dummy``, when given)."""
    (tmp_path / "rig.toml").write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n[model]\ndeclared = ["viscous"]\n')
    text = ('[device]\nrig = "rig.toml"\n[hardware]\ngpio_backend = "mock"\nsensor = "dummy"\n'
            '[hardware.solenoid]\npin = 17\n[hardware.encoder]\nport = "/dev/ttyUSB0"\n')
    path = tmp_path / "appliance.toml"
    path.write_text(text + (f"[hardware.dummy]\n{dummy}" if dummy is not None else ""))
    return path


def test_a_dummy_sensor_registered_in_one_place_is_the_devices_sensor_and_in_moi_check(tmp_path: Path, registered):
    config = load_config(_dummy_config(tmp_path))
    assert config.hardware is not None and config.hardware.sensor == "dummy"
    assert config.hardware.sensors["dummy"] == DummySettings(bus="/dev/i2c-3")
    assert config.hardware.encoder is None, "another sensor's table is not the chosen sensor's settings"
    assert config.to_dict()["hardware"]["dummy"] == {"bus": "/dev/i2c-3", "address": 0x68}
    devices = build_devices(config)
    try:
        assert DummySensor.built == ["device on /dev/i2c-3"]
        assert isinstance(devices.sensor, SimulatedAngleSensor) and devices.sensor.source == "inclinometer"
    finally:
        devices.close()
    [line] = [c for c in check_config(config) if c.what == "inclinometer bus"]
    assert not line.ok and "/dev/i2c-3" in line.detail
    assert not [c for c in check_config(config) if "encoder" in c.what], "the encoder's health is the encoder's"


def test_a_dummy_sensor_brings_its_own_settings_table(tmp_path: Path, registered):
    """[hardware.dummy] is the dummy's: its keys, defaults, docs and checks, in the file and the reference."""
    reference = reference_markdown()
    assert "**[hardware.dummy]**" in reference and "| `bus` | str | **required** | the inclinometer's I2C bus |" in reference
    assert "an I2C inclinometer ([hardware.dummy])" in reference, "the [hardware] sensor key says it"
    assert "| `dummy` | table | – | [hardware.dummy] bus, address |" in reference
    assert "'dummy'" in reference.split("| `sensor` |")[1].split("\n")[0], "a choice of [hardware] sensor"
    for table, message in (
            (None, r'\[hardware\] dummy: missing: sensor = "dummy" needs a \[hardware.dummy\] table \(bus = "/dev/i2c-1"\)'),
            ('bus = "/dev/i2c-3"\nadress = 3\n', r"\[hardware.dummy\]: unknown key 'adress' \(did you mean 'address'\?\)"),
            ('bus = "/dev/i2c-3"\naddress = 200\n', r"\[hardware.dummy\] address: expected an integer in \[0, 127\], got 200"),
            ('bus = "/dev/spi0"\n', r'\[hardware.dummy\] bus: expected an I2C bus like "/dev/i2c-1", got \'/dev/spi0\'')):
        with pytest.raises(ConfigError, match=message):
            load_config(_dummy_config(tmp_path, table))


def test_a_sensor_table_is_unknown_until_its_sensor_is_registered(tmp_path: Path):
    with pytest.raises(ConfigError, match=r"\[hardware\]: unknown key 'dummy'"):
        load_config(_dummy_config(tmp_path))
    assert "[hardware.dummy]" not in reference_markdown()


def test_the_systemd_unit_grants_every_hardware_sensor_its_devices():
    from tests.service.config.test_service_systemd import unit

    u = unit()
    groups = set(u["SupplementaryGroups"][0].split())
    allowed = {line.split()[0] for line in u["DeviceAllow"]}
    for name in registry.names(hardware=True):
        kind = registry.sensor(name)
        assert set(kind.GROUPS) <= groups, name
        assert set(kind.DEVICE_CLASSES) <= allowed, name
