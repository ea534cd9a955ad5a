"""A publisher is one class registered in one place: the daemon drives it through the port and names none."""

from __future__ import annotations

import dataclasses
import threading
from typing import Any

import pytest

from service.config.appliance import parse_config, reference_markdown
from service.errors import ConfigError
from service.publish import registry
from service.publish.port import ApplianceView, Publisher
from service.publish.registry import PublisherEntry
from service.settings.schema import PublisherTable
from tests.service.conftest import appliance_doc


@dataclasses.dataclass(frozen=True)
class DummySettings:
    topic: str = "parts"
    window: int = 4


def _check(values, fail) -> None:
    if values["topic"] == values["topic"].upper():
        raise fail("topic", f"expected a topic with lower-case letters, got {values['topic']!r}")


#: its configuration table, as a publisher's settings module declares it
TABLE = PublisherTable(DummySettings, {"topic": dict(doc="where the parts go"), "window": dict(doc="", min=1)},
                       enabled="publish to the dummy", check=_check)


class DummyPublisher(Publisher):
    """Records what the daemon hands it."""

    NAME = "dummy"
    made: list["DummyPublisher"] = []

    def __init__(self, settings: DummySettings, appliance: ApplianceView) -> None:
        self.settings = settings
        self.appliance = appliance
        self.calls: list[tuple[str, Any]] = []
        self.results = threading.Event()
        self.running = False

    @classmethod
    def build(cls, settings: DummySettings, appliance: ApplianceView) -> "DummyPublisher":
        made = cls(settings, appliance)
        cls.made.append(made)
        return made

    def start(self) -> None:
        self.running = True

    def stop(self) -> None:
        self.running = False
        self.calls.append(("stop", None))

    def where(self) -> str:
        return f"dummy on {self.settings.topic}"

    def health(self) -> dict[str, Any]:
        return {"topic": self.settings.topic}

    def on_state(self, message, event) -> None:
        self.calls.append(("state", message["state"]))

    def on_result(self, stored, measurement) -> None:
        self.calls.append(("result", stored.payload["J"]))
        self.results.set()


PUBLISHER = DummyPublisher


@pytest.fixture
def registered(monkeypatch):
    """The one line that adds the dummy publisher: its entry in the registry (this module is its publisher
    and its settings module)."""
    monkeypatch.setattr(registry, "PUBLISHERS", (*registry.PUBLISHERS, PublisherEntry("dummy", __name__, __name__)))


def test_a_registered_publisher_has_its_configuration_table(registered):
    assert parse_config({}).publishers["dummy"] is None, "off without its table"
    config = parse_config({"dummy": {"topic": "rotors"}})
    assert config.publishers["dummy"] == DummySettings(topic="rotors", window=4)
    assert config.to_dict()["dummy"] == {"topic": "rotors", "window": 4}
    assert parse_config({"dummy": {"enabled": False}}).publishers["dummy"] is None
    with pytest.raises(ConfigError, match=r"\[dummy\] window: expected an integer >= 1, got 0"):
        parse_config({"dummy": {"window": 0}})
    with pytest.raises(ConfigError, match=r"\[dummy\] topic: expected a topic with lower-case letters"):
        parse_config({"dummy": {"topic": "ROTORS"}})
    with pytest.raises(ConfigError, match=r"unknown key 'topc' \(did you mean 'topic'\?\)"):
        parse_config({"dummy": {"topc": "x"}})
    assert "**[dummy]**" in reference_markdown() and "| `topic` | str | `\"parts\"` | where the parts go |" in reference_markdown()


def test_every_registered_publisher_is_named_by_the_configuration_and_the_appliance():
    """``Config.<name>`` and ``Appliance.<name>`` are written out (readers and mypy see them): one per entry."""
    from service.daemon import Appliance
    from service.settings.config import Config

    for entry in registry.PUBLISHERS:
        assert isinstance(getattr(Config, entry.name, None), property), f"Config.{entry.name}"
        assert isinstance(getattr(Appliance, entry.name, None), property), f"Appliance.{entry.name}"
    config = parse_config({"mqtt": {"host": "broker.local"}})
    assert config.mqtt is config.publishers["mqtt"] and config.mqtt.host == "broker.local"
    assert config.opcua is None and config.modbus is not None


def test_the_publishers_bring_their_own_start_checks_descriptors_and_contact():
    from service.config.appliance import whom_to_call
    from service.config.check import check_config, descriptor_budget

    config = parse_config({"modbus": {"port": 0, "max_connections": 7}, "web": {"port": 0, "contact": "Ines, 4711"},
                           "mqtt": {"host": "broker.local", "tls": True, "ca_file": "/nonexistent/ca.pem"}})
    found = {c.what: c for c in check_config(config)}
    assert found["Modbus TCP port"].ok and found["web page port"].ok
    assert not found["MQTT ca_file"].ok and "does not exist" in found["MQTT ca_file"].detail
    assert "Modbus 7, web " in descriptor_budget(config, limit=1024).detail
    assert whom_to_call(config) == "Ines, 4711"
    assert whom_to_call(parse_config({"web": {"enabled": False}})) is None


def test_an_unregistered_table_is_unknown():
    with pytest.raises(ConfigError, match=r"unknown table 'dummy'"):
        parse_config({"dummy": {"topic": "rotors"}})


def test_a_dummy_publisher_registered_in_one_place_gets_states_and_results(tmp_path, registered, appliance_factory):
    DummyPublisher.made.clear()
    app = appliance_factory(appliance_doc(tmp_path / "state", dummy={"topic": "rotors"}))
    [dummy] = DummyPublisher.made
    assert dummy.running and app.app.publisher("dummy") is dummy
    assert app.app.publisher_health()["dummy"] == {"topic": "rotors"}
    assert dummy.appliance.config.device_id == "test-rig"
    app.press()
    assert dummy.results.wait(30), "no result handed to the dummy publisher"
    app.wait_done(1)
    states = [s for kind, s in dummy.calls if kind == "state"]
    assert states[0] == "IDLE" and "CAPTURING" in states and "PUBLISHING" in states
    [(_, J)] = [c for c in dummy.calls if c[0] == "result"]
    assert abs(J / app.app.devices.sim.inertia - 1) < 2e-3
    assert app.stop() == 0
    assert dummy.calls[-1] == ("stop", None) and not dummy.running


def test_a_publisher_whose_thread_died_stops_the_daemon(tmp_path, monkeypatch, registered, appliance_factory):
    class Failing(DummyPublisher):
        def failure(self) -> str | None:
            return "the dummy thread stopped"

    monkeypatch.setattr(__import__(__name__, fromlist=["PUBLISHER"]), "PUBLISHER", Failing)
    app = appliance_factory(appliance_doc(tmp_path / "state", dummy={}))
    app.thread.join(30)
    assert not app.thread.is_alive() and app.app.exit_status == 3
