"""Attacks on the running appliance (simulated rig, everything on loopback): hostile MQTT payloads,
illegal Modbus writes, connection floods. Each attack is bounded in count and time."""

from __future__ import annotations

import json

import pytest

from service.mqtt import MqttService, MqttSettings
from service.store import Store

from .conftest import appliance_doc, wait_until

pytestmark = pytest.mark.broker


def test_a_deeply_nested_json_command_neither_stops_mqtt_nor_its_acknowledgements(tmp_path, broker, appliance_factory,
                                                                                  consumer_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.connected_event.wait(10)
    c = consumer_factory(broker.port, ["moi/test-rig/result"])
    c.wait_subscribed()
    c.publish("moi/test-rig/cmd/measure", "[" * 2000 + "]" * 2000)  # 4 kB; a RecursionError for json.loads
    app.wait_done(1)
    c.publish("moi/test-rig/cmd/measure", "{" + '"a":{' * 600 + "}" * 601)
    app.wait_done(2)
    c.publish("moi/test-rig/cmd/measure", json.dumps({"id": "after-the-attack"}))
    app.wait_done(3)
    c.wait(lambda c: len(c.unique_results()) == 3, 20, "three results")
    # the acknowledgements are still read: the outbox empties
    wait_until(lambda: app.app.store.outbox_count() == 0, 10, what="the outbox to drain")
    assert app.app.mqtt.network_thread_alive() and app.app.live_status().mqtt_connected
    assert app.app.mqtt.callback_errors == 0
    assert app.stop() == 0


def test_an_exception_in_a_command_handler_is_logged_and_the_next_command_still_arrives(tmp_path, broker,
                                                                                         consumer_factory):
    got: list[str] = []

    def on_command(name: str, source: str) -> None:
        got.append(name)
        if len(got) == 1:
            raise RuntimeError("handler bug")

    store = Store(tmp_path / "state")
    svc = MqttService(MqttSettings(host="127.0.0.1", port=broker.port, reconnect_min=0.1, reconnect_max=0.5),
                      "rig", store, on_command=on_command)
    svc.start()
    try:
        assert svc.connected_event.wait(10)
        c = consumer_factory(broker.port, ["moi/rig/status"])
        c.wait_subscribed()
        c.publish("moi/rig/cmd/measure", "")
        c.publish("moi/rig/cmd/abort", "")
        wait_until(lambda: len(got) == 2, 10, what="the second command")
        assert got == ["trigger", "abort"]
        assert svc.callback_errors == 1 and "handler bug" in svc.last_error
        assert svc.network_thread_alive()
    finally:
        svc.stop()
        store.close()


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_a_dead_mqtt_network_thread_stops_the_daemon_and_its_watchdog(tmp_path, broker, appliance_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.connected_event.wait(10)

    def broken_loop(timeout: float = 1.0):
        raise RuntimeError("simulated death of the network thread")

    app.app.mqtt.client._loop = broken_loop  # what an escaped callback exception did: loop_forever ends
    app.thread.join(20)
    assert not app.thread.is_alive(), "the daemon kept running (and feeding the watchdog) without MQTT"
    assert app.app.exit_status == 3
