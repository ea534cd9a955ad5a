"""A sensor is one module registered in one place: the device builder, `moi check` and the web page hold a sensor
kind and name none."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from drivers.sensor import SimulatedAngleSensor
from firmware_host import SequencerConfig
from measurement.errors import InvalidInput
from service.config.appliance import SimulationSettings, parse_config
from service.config.check import check_config
from service.devices.hardware import build_devices, build_simulated
from service.devices.sensors import registry
from service.devices.sensors.port import SensorKind
from service.devices.sensors.registry import SensorEntry


class DummySensor(SensorKind):
    """An inclinometer read in process: the driver, its simulated twin and its health, nothing else."""

    NAME = "dummy"
    LABEL = "inclinometer"
    MAX_TIME_SCALE = 5.0
    TIME_SCALE_REASON = "the dummy's bus is slow"
    built: list[str] = []

    @classmethod
    def build(cls, config, clock):
        cls.built.append("device")
        return SimulatedAngleSensor(lambda t: 0.1, clock, rate=100.0, source="inclinometer")

    @classmethod
    def simulate(cls, sim, pendulum, clock, notes):
        cls.built.append("twin")
        notes.append("simulated dummy inclinometer")
        return (SimulatedAngleSensor(pendulum.angle, clock, rate=sim.rate, source="inclinometer"),
                [lambda: cls.built.append("bus stopped")])

    @classmethod
    def health(cls, config):
        return [("inclinometer bus", False, "/dev/i2c-1 does not exist")]


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


def test_a_dummy_sensor_registered_in_one_place_is_the_devices_sensor_and_in_moi_check(tmp_path: Path, registered):
    (tmp_path / "rig.toml").write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n[model]\ndeclared = ["viscous"]\n')
    config = parse_config({"device": {"rig": str(tmp_path / "rig.toml")},
                           "hardware": {"gpio_backend": "mock", "solenoid": {"pin": 17},
                                        "encoder": {"port": "/dev/ttyUSB0"}}})
    assert config.hardware is not None
    config = dataclasses.replace(config, hardware=dataclasses.replace(config.hardware, sensor="dummy"))
    devices = build_devices(config)
    try:
        assert DummySensor.built == ["device"]
        assert isinstance(devices.sensor, SimulatedAngleSensor) and devices.sensor.source == "inclinometer"
    finally:
        devices.close()
    [line] = [c for c in check_config(config) if c.what == "inclinometer bus"]
    assert not line.ok and "/dev/i2c-1" in line.detail
    assert not [c for c in check_config(config) if "encoder" in c.what], "the encoder's health is the encoder's"


def test_the_systemd_unit_grants_every_hardware_sensor_its_devices():
    from .test_service_systemd import unit

    u = unit()
    groups = set(u["SupplementaryGroups"][0].split())
    allowed = {line.split()[0] for line in u["DeviceAllow"]}
    for name in registry.names(hardware=True):
        kind = registry.sensor(name)
        assert set(kind.GROUPS) <= groups, name
        assert set(kind.DEVICE_CLASSES) <= allowed, name
