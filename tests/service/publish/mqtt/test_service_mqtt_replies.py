"""Every MQTT command gets an answer: the daemon behind the real Mosquitto, an MQTT 5 client with a response
topic and correlation data, and a plain client reading the `reply` topic."""

from __future__ import annotations

import json
import threading
import time

import paho.mqtt.client as mqtt
from paho.mqtt.enums import CallbackAPIVersion
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from tests.service.conftest import appliance_doc

BASE = "moi/test-rig"


class V5Client:
    """An MQTT 5 client that records (topic, JSON, correlation data) of what arrives."""

    def __init__(self, port: int, topics: list[str]) -> None:
        self.got: list[tuple[str, dict, bytes | None]] = []
        self.cond = threading.Condition()
        subscribed = threading.Event()
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id="plant-mes", protocol=mqtt.MQTTv5)
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe([(t, 1) for t in topics])
        self.client.on_subscribe = lambda *a: subscribed.set()
        self.client.on_message = self._on_message
        self.client.connect("127.0.0.1", port, keepalive=10)
        self.client.loop_start()
        assert subscribed.wait(10), "not subscribed"

    def _on_message(self, client, userdata, msg) -> None:
        corr = getattr(msg.properties, "CorrelationData", None)
        with self.cond:
            self.got.append((msg.topic, json.loads(msg.payload), corr))
            self.cond.notify_all()

    def send(self, command: str, payload: dict, response_topic: str | None = None, correlation: bytes | None = None):
        props = None
        if response_topic is not None:
            props = Properties(PacketTypes.PUBLISH)
            props.ResponseTopic = response_topic
            props.CorrelationData = correlation
        self.client.publish(f"{BASE}/cmd/{command}", json.dumps(payload), qos=1, properties=props).wait_for_publish(5)

    def wait_for(self, predicate, timeout: float = 20):
        deadline = time.monotonic() + timeout
        with self.cond:
            while True:
                found = [g for g in self.got if predicate(g)]
                if found:
                    return found[0]
                left = deadline - time.monotonic()
                assert left > 0, f"no such reply in {self.got}"
                self.cond.wait(left)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def test_commands_are_answered_accepted_done_or_refused_with_the_reason(tmp_path, broker, appliance_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.subscribed_event.wait(10)
    mine = f"{BASE}/reply/plant-mes"
    c = V5Client(broker.port, [mine, f"{BASE}/reply"])
    try:
        c.send("measure", {"id": "m1"}, response_topic=mine, correlation=b"\x01corr")
        accepted = c.wait_for(lambda g: g[1]["id"] == "m1" and g[1]["status"] == "accepted")
        assert accepted[0] == mine and accepted[2] == b"\x01corr" and accepted[1]["command"] == "measure"
        done = c.wait_for(lambda g: g[1]["id"] == "m1" and g[1]["status"] == "done", 30)
        assert done[0] == mine and done[2] == b"\x01corr"
        assert done[1]["uuid"] == app.app.stored[0] and done[1]["seq"] >= 1
        app.wait_done(1)

        # no response topic: the reply topic, with the command's id; each refusal changes nothing
        c.send("recipe", {"id": "r1", "recipe": "no-such-part"})
        r = c.wait_for(lambda g: g[1]["id"] == "r1")[1]
        assert (r["status"], r["reason"]) == ("refused", "unknown_recipe") and "no-such-part" in r["detail"]
        assert app.app.parts.recipe is None
        c.send("set", {"id": "s1"})
        r = c.wait_for(lambda g: g[1]["id"] == "s1")[1]
        assert (r["status"], r["reason"]) == ("refused", "malformed")
        c.send("part_id", {"id": "p1", "part_id": "bad\u00e9id"})
        r = c.wait_for(lambda g: g[1]["id"] == "p1")[1]
        assert (r["status"], r["reason"]) == ("refused", "malformed") and app.app.parts.part_id is None
        c.send("measure", {"id": "m1"})  # the same id again (QoS 1 may deliver twice): not a second run
        r = c.wait_for(lambda g: g[1]["id"] == "m1" and g[1]["status"] == "refused")[1]
        assert r["reason"] == "duplicate" and len(app.app.stored) == 1
        c.send("abort", {"id": "a1"})
        r = c.wait_for(lambda g: g[1]["id"] == "a1")[1]
        assert (r["status"], r["reason"]) == ("refused", "nothing_to_abort")
        c.send("part_id", {"id": "p2", "part_id": "SN-42"})
        r = c.wait_for(lambda g: g[1]["id"] == "p2")[1]
        assert r["status"] == "done" and app.app.parts.part_id == "SN-42"
    finally:
        c.close()


def test_a_broker_spoken_to_in_mqtt_3_1_1_gets_the_answers_on_the_reply_topic(tmp_path, broker, consumer_factory):
    from service.persistence.store import Store
    from service.publish.mqtt.client import MqttService, MqttSettings
    from service.publish.replies import CommandReply

    def on_command(name, source, data=None, reply=None):
        reply(CommandReply(name, "refused", "busy"))  # as the daemon answers while a measurement runs

    store = Store(tmp_path / "state")
    svc = MqttService(MqttSettings(host="127.0.0.1", port=broker.port, protocol="3.1.1", reconnect_min=0.1,
                                   reconnect_max=0.5), "rig", store, on_command=on_command)
    svc.start()
    try:
        assert svc.subscribed_event.wait(10) and not svc.v5
        c = consumer_factory(broker.port, ["moi/rig/reply"])
        c.wait_subscribed()
        c.publish("moi/rig/cmd/recipe", json.dumps({"id": "r-9", "recipe": "rotor"}))
        c.wait(lambda c: c.on("/reply"), 10, "the reply")
        r = json.loads(c.on("/reply")[0])
        assert (r["id"], r["command"], r["status"], r["reason"]) == ("r-9", "recipe", "refused", "busy")
    finally:
        svc.stop()
        store.close()
