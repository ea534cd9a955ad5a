"""The MQTT side against a real Mosquitto: outbox delivery, status/last will, commands, discovery."""

from __future__ import annotations

import json
import re
import threading

import pytest

from service.persistence.store import Store
from service.publish.mqtt.client import MqttService, MqttSettings
from service.publish.mqtt.discovery import discovery_messages
from service.publish.mqtt.topics import Topics

pytestmark = pytest.mark.broker


def settings(port: int, **kw) -> MqttSettings:
    return MqttSettings(host="127.0.0.1", port=port, reconnect_min=0.1, reconnect_max=0.5, keepalive=5, **kw)


def add_rows(store: Store, n: int) -> list[str]:
    uuids = []
    for i in range(n):
        m = store.record(status="ok", trigger="test", device_id="d1", software_version="0", started_at=1.0,
                         finished_at=2.0, result={"J": 0.01 * (i + 1)},
                         build_payload=lambda uuid, seq: {"uuid": uuid, "seq": seq, "J": 0.01 * seq},
                         enqueue={"mqtt": ("result",)})
        uuids.append(m.uuid)
    return uuids


def test_outbox_rows_are_published_and_deleted_only_after_the_broker_acknowledges(tmp_path, broker, consumer_factory):
    store = Store(tmp_path)
    uuids = add_rows(store, 3)  # stored before the client even exists
    c = consumer_factory(broker.port, ["moi/d1/#"])
    c.wait_subscribed()
    svc = MqttService(settings(broker.port), "d1", store)
    svc.start()
    try:
        c.wait(lambda c: len(c.unique_results()) == 3, 10, "three results")
        assert svc.sender.wait_empty(10)
        assert store.outbox_count() == 0
        assert list(c.unique_results()) == uuids  # in order
        assert all(store.get(u).published_at is not None for u in uuids)
        assert c.on("/status")[-1] == b"online"
    finally:
        svc.stop()
    c.wait(lambda c: c.on("/status")[-1:] == [b"offline"], 5, "offline status at a clean stop")
    store.close()


def test_results_stored_while_the_broker_is_down_go_out_when_it_is_back(tmp_path, persistent_broker, consumer_factory):
    store = Store(tmp_path)
    c = consumer_factory(persistent_broker.port, ["moi/d1/result"], client_id="dedupe-consumer", persistent=True)
    c.wait_subscribed()
    svc = MqttService(settings(persistent_broker.port), "d1", store)
    svc.start()
    try:
        assert svc.connected_event.wait(10)
        persistent_broker.stop()
        uuids = add_rows(store, 3)
        svc.wake()
        assert store.outbox_count() == 3
        persistent_broker.start()
        c.wait(lambda c: len(c.unique_results()) == 3, 20, "three results after the broker came back")
        assert set(c.unique_results()) == set(uuids)
        assert svc.sender.wait_empty(10) and store.outbox_count() == 0
    finally:
        svc.stop()
        store.close()


def test_commands_trigger_once_and_retained_or_repeated_ids_do_not(tmp_path, broker, consumer_factory):
    got: list[tuple[str, str]] = []
    cond = threading.Condition()

    def on_command(name, source, data=None, reply=None):
        with cond:
            got.append((name, source))
            cond.notify_all()

    store = Store(tmp_path)
    c = consumer_factory(broker.port, ["moi/d1/status"])
    c.wait_subscribed()
    # a retained command left on the broker: it would fire at every (re)connect if it were obeyed
    c.publish("moi/d1/cmd/measure", "{}", retain=True)
    svc = MqttService(settings(broker.port), "d1", store, on_command=on_command)
    svc.start()
    try:
        assert svc.connected_event.wait(10)
        c.wait(lambda c: c.on("/status") == [b"online"], 5, "online")  # our subscriptions are in place by then
        c.publish("moi/d1/cmd/measure", json.dumps({"id": "a1"}))
        c.publish("moi/d1/cmd/measure", json.dumps({"id": "a1"}))  # QoS 1 duplicate of the same command
        c.publish("moi/d1/cmd/abort", "now")
        c.publish("moi/d1/cmd/measure", "go")
        with cond:
            assert cond.wait_for(lambda: len(got) >= 3, 10)
        # a marker after everything: when it arrives, every earlier command was handled
        c.publish("moi/d1/cmd/abort", json.dumps({"id": "marker"}))
        with cond:
            assert cond.wait_for(lambda: len(got) >= 4, 10)
        assert got == [("trigger", "mqtt"), ("abort", "mqtt"), ("trigger", "mqtt"), ("abort", "mqtt")]
    finally:
        svc.stop()
        store.close()


def test_home_assistant_discovery_is_retained_and_names_the_result_topic(tmp_path, broker, consumer_factory):
    store = Store(tmp_path)
    svc = MqttService(settings(broker.port, home_assistant=True), "d1", store, software_version="1.2")
    svc.recipes = ("shaft-A", "rotor")
    svc.start()
    try:
        assert svc.connected_event.wait(10)
        expected = discovery_messages(svc.settings, Topics("moi", "d1"), "d1", "1.2", svc.recipes)
        early = consumer_factory(broker.port, ["homeassistant/#"], client_id="early")
        early.wait(lambda c: len(c.messages) >= len(expected), 10, "discovery configs (all at the broker)")
        late = consumer_factory(broker.port, ["homeassistant/#"])  # subscribes after: sees retained configs
        late.wait(lambda c: len(c.messages) >= len(expected), 10, "discovery configs")
        assert all(retained for _, _, retained in late.messages)
        j = json.loads({t: p for t, p, _ in late.messages}["homeassistant/sensor/d1/J/config"])
        assert j["state_topic"] == "moi/d1/result/last" and j["availability_topic"] == "moi/d1/status"
        assert j["unit_of_measurement"] == "kg·m²"
        assert j["default_entity_id"] == "sensor.moi_d1_j" and j["object_id"] == "moi_d1_j"
        assert j["origin"]["name"] == "moi" and j["origin"]["sw_version"] == "1.2"
        configs = {t: json.loads(p) for t, p, _ in late.messages}
        assert "homeassistant/sensor/d1/J_object/config" in configs
        assert configs["homeassistant/button/d1/abort/config"]["command_topic"] == "moi/d1/cmd/abort"
        assert configs["homeassistant/binary_sensor/d1/fit_not_converged/config"]["device_class"] == "problem"
        for information in ("outliers_removed", "unmodeled_residual"):
            assert "device_class" not in configs[f"homeassistant/binary_sensor/d1/{information}/config"]
        flags = [t for t, _, _ in late.messages if t.startswith("homeassistant/binary_sensor/")]
        assert "homeassistant/binary_sensor/d1/unmodeled_residual/config" in flags
        verdict = json.loads({t: p for t, p, _ in late.messages}["homeassistant/sensor/d1/verdict/config"])
        assert verdict["state_topic"] == "moi/d1/result/last" and "value_json.verdict" in verdict["value_template"]
        select = configs["homeassistant/select/d1/recipe/config"]
        assert select["options"] == ["none", "shaft-A", "rotor"] and select["command_topic"] == "moi/d1/cmd/recipe"
        assert select["state_topic"] == "moi/d1/recipe"
        text = configs["homeassistant/text/d1/next_part_id/config"]
        assert text["command_topic"] == "moi/d1/cmd/part_id" and text["max"] == 20
        for c in configs.values():  # Home Assistant's entity ids: lower case, digits, underscores
            assert re.fullmatch(r"[a-z_]+\.[a-z0-9_]+", c["default_entity_id"]), c["default_entity_id"]
            if c.get("state_class") == "measurement":
                assert c.get("unit_of_measurement"), c["name"]
        # the state the select and the text show, retained
        state = consumer_factory(broker.port, ["moi/d1/recipe", "moi/d1/part_id"], client_id="state")
        state.wait(lambda c: len(c.messages) >= 2, 10, "the retained recipe and part ID")
        assert json.loads(state.on("/recipe")[0]) == {"name": "none", "number": 0}
    finally:
        svc.stop()
        store.close()


def test_a_retained_document_published_while_the_broker_is_down_is_there_when_it_is_back(
        tmp_path, persistent_broker, consumer_factory):
    store = Store(tmp_path)
    svc = MqttService(settings(persistent_broker.port), "d1", store)
    svc.start()
    try:
        assert svc.connected_event.wait(10)
        persistent_broker.stop()
        svc.publish_retained(svc.topics.tensor, {"uuid": "set-1", "tensor": [[1.0, 0.0, 0.0]] * 3})
        persistent_broker.start()
        # a consumer that subscribes after the outage finds the latest tensor retained
        c = consumer_factory(persistent_broker.port, ["moi/d1/tensor"])
        c.wait_subscribed()
        c.wait(lambda c: any(json.loads(p).get("uuid") == "set-1" for p in c.on("/tensor")), 20,
               "the tensor retained after the broker came back")
    finally:
        svc.stop()
        store.close()


def test_entity_ids_are_valid_for_any_device_id():
    msgs = discovery_messages(MqttSettings(home_assistant=True), Topics("moi", "HA-Test.2"), "HA-Test.2", "1")
    ids = {c["default_entity_id"] for _, c in msgs}
    assert "sensor.moi_ha_test_2_j" in ids and "sensor.moi_ha_test_2_omega_n" in ids
    assert all(re.fullmatch(r"[a-z_]+\.[a-z0-9_]+", i) for i in ids)
    assert len(ids) == len(msgs)  # no two entities collapse into one id
