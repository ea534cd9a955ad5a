"""A publisher is one class registered in one place: the daemon drives it through the port and names none."""

from __future__ import annotations

import dataclasses
import threading
from typing import Any

from service.publish import port
from service.publish.port import ApplianceView, Publisher, PublisherEntry

from .conftest import appliance_doc


@dataclasses.dataclass(frozen=True)
class DummySettings:
    topic: str = "parts"


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


def test_a_dummy_publisher_registered_in_one_place_gets_states_and_results(tmp_path, monkeypatch, appliance_factory):
    monkeypatch.setattr(port, "PUBLISHERS", (*port.PUBLISHERS, PublisherEntry("dummy", __name__)))
    DummyPublisher.made.clear()
    # the [dummy] table as the configuration would hold it
    from service.config.appliance import Config
    monkeypatch.setattr(Config, "dummy", DummySettings(topic="rotors"), raising=False)
    app = appliance_factory(appliance_doc(tmp_path / "state"))
    [dummy] = DummyPublisher.made
    assert dummy.running and app.app.dummy is dummy
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


def test_a_publisher_whose_thread_died_stops_the_daemon(tmp_path, monkeypatch, appliance_factory):
    class Failing(DummyPublisher):
        def failure(self) -> str | None:
            return "the dummy thread stopped"

    monkeypatch.setattr(port, "PUBLISHERS", (*port.PUBLISHERS, PublisherEntry("dummy", __name__)))
    monkeypatch.setattr(__import__(__name__, fromlist=["PUBLISHER"]), "PUBLISHER", Failing)
    from service.config.appliance import Config
    monkeypatch.setattr(Config, "dummy", DummySettings(), raising=False)
    app = appliance_factory(appliance_doc(tmp_path / "state"))
    app.thread.join(30)
    assert not app.thread.is_alive() and app.app.exit_status == 3
