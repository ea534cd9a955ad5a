"""The MQTT contract as mosquitto's own clients (mosquitto_sub / mosquitto_pub, not paho) see it, against the daemon
behind a real Mosquitto: what docs/service.md says is what arrives."""

from __future__ import annotations

import json
import re
from collections import Counter

import pytest

from service.publish.payload import ENVELOPE_KEYS, PAYLOAD_SCHEMA
from tests.service.conftest import REPO, appliance_doc, wait_until
from tests.service.publish.mqtt.mosquitto_clients import MosquittoSub, mosquitto_pub, require_clients

pytestmark = pytest.mark.broker

BASE = "moi/test-rig"
#: the keys a PUBLISHING state message adds once the store holds the result (docs/service.md)
RESULT_KEYS = {"J", "J_std", "omega_n"}


@pytest.fixture
def sub(broker):
    require_clients()
    made: list[MosquittoSub] = []

    def make(*suffixes: str) -> MosquittoSub:
        s = MosquittoSub(broker.port, [f"{BASE}/{x}" for x in suffixes])
        made.append(s)
        return s

    yield make
    for s in made:
        s.close()


def documented_state_keys() -> set[str]:
    """The keys docs/service.md gives the `state` topic's messages."""
    row = next(line for line in (REPO / "docs" / "service.md").read_text(encoding="utf-8").splitlines()
               if line.startswith("| `moi/<id>/state` |"))
    keys = re.search(r"`\{([^}]*)\}`", row)
    assert keys, row
    return set(re.findall(r'"(\w+)"', keys.group(1)))


def test_every_state_message_has_the_documented_keys_and_a_result_its_envelope(tmp_path, broker, appliance_factory,
                                                                              sub):
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.subscribed_event.wait(10)
    s = sub("status", "state", "result", "reply")
    documented = documented_state_keys()
    assert {"transition", "time", "state", "at"} <= documented
    # the retained state right after the start: the daemon's first message, before any transition
    [first] = s.wait(lambda s: s.payloads("/state"), 10, "the retained state")
    assert set(first) == documented and (first["state"], first["transition"]) == ("IDLE", 0)
    assert isinstance(first["time"], float) and first["device_id"] == "test-rig"
    assert s.on("/status")[0]["payload"] == "online" and s.on("/status")[0]["retain"] == 1

    mosquitto_pub(broker.port, f"{BASE}/cmd/measure", json.dumps({"id": "m-1"}))
    [result] = s.wait(lambda s: s.payloads("/result"), 60, "the result")
    assert result["payload_schema"] == PAYLOAD_SCHEMA and set(ENVELOPE_KEYS) <= set(result)
    app.wait_done(1)
    s.wait(lambda s: [r for r in s.payloads("/reply") if r["status"] == "done"], 20, "the measure's reply done")
    s.wait(lambda s: s.payloads("/state")[-1]["state"] == "IDLE" and len(s.payloads("/state")) > 2, 20, "IDLE again")
    states = s.payloads("/state")
    for m in states:
        assert documented <= set(m) <= documented | RESULT_KEYS, m
    assert [m["transition"] for m in states] == list(range(len(states)))  # none lost, counted from the start's 0
    assert [(r["id"], r["status"]) for r in s.payloads("/reply")] == [("m-1", "accepted"), ("m-1", "done")]


@pytest.mark.parametrize("protocol", ["5", "3.1.1"])
def test_a_retained_command_runs_once_when_it_is_published_and_never_again_from_the_brokers_copy(
        tmp_path, broker, appliance_factory, sub, protocol):
    """The broker hands a retained command published while the daemon is connected on as a plain message (MQTT
    3.1.1 and 5 alike): it runs, once, as Node-RED's or Home Assistant's button with retain set means it to. The
    copy the broker keeps comes with the retain flag at each later subscription and never runs."""
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port, mqtt={"protocol": protocol}))
    mqtt = app.app.mqtt
    assert mqtt.v5 == (protocol == "5")
    assert mqtt.subscribed_event.wait(10)
    s = sub("reply")
    mosquitto_pub(broker.port, f"{BASE}/cmd/measure", json.dumps({"id": "kept"}), retain=True)
    s.wait(lambda s: [r for r in s.payloads("/reply") if r["status"] == "done"], 60, "the retained command's run")
    app.wait_done(1)
    mqtt.client.socket().close()  # the connection drops: paho reconnects and subscribes again
    wait_until(lambda: mqtt.connections == 2 and mqtt.subscribed_event.is_set(), 20, what="the new subscription")
    mosquitto_pub(broker.port, f"{BASE}/cmd/abort", json.dumps({"id": "probe-1"}))  # delivered after the copy
    s.wait(lambda s: [r for r in s.payloads("/reply") if r["id"] == "probe-1"], 20, "the probe's reply")
    mosquitto_pub(broker.port, f"{BASE}/cmd/measure", None, retain=True)  # how the copy is cleared: no command
    mosquitto_pub(broker.port, f"{BASE}/cmd/abort", json.dumps({"id": "probe-2"}))
    s.wait(lambda s: [r for r in s.payloads("/reply") if r["id"] == "probe-2"], 20, "the second probe's reply")
    assert [(r["id"], r["status"]) for r in s.payloads("/reply")] == [
        ("kept", "accepted"), ("kept", "done"), ("probe-1", "refused"), ("probe-2", "refused")]
    assert len(app.app.stored) == 1


def test_broken_json_on_cmd_recipe_is_malformed_and_no_reply_names_a_folder(tmp_path, broker, appliance_factory, sub):
    recipes = tmp_path / "plant-secret" / "recipes"
    recipes.mkdir(parents=True)
    (recipes / "a.toml").write_text('[recipe]\nname = "rotor-a"\nnumber = 3\nnominal = 0.0125\ntolerance_percent = 2\n')
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port,
                                          recipes={"directory": str(recipes)}))
    assert app.app.mqtt.subscribed_event.wait(10)
    s = sub("reply")
    sent = ['{"recipe": "rotor-a"', "[3]", '{"recipe": "no-such"}', "no-such", "{broken", '{"id": "x", "recipe": 3}']
    for payload in sent:
        mosquitto_pub(broker.port, f"{BASE}/cmd/recipe", payload)
    replies = s.wait(lambda s: len(s.payloads("/reply")) >= len(sent) and s.payloads("/reply"), 20, "every reply")
    # the client refuses what it cannot read at once, the daemon the rest from its main loop: counted, not ordered
    assert Counter((r["status"], r["reason"]) for r in replies) == {
        ("refused", "malformed"): 3, ("refused", "unknown_recipe"): 2, ("done", None): 1}
    assert all("no recipe 'no-such' (known: 3 rotor-a)" in r["detail"] for r in replies if r["reason"] == "unknown_recipe")
    for r in replies:
        assert "plant-secret" not in r["detail"] and str(tmp_path) not in r["detail"] and "/" not in r["detail"], r
    assert app.app.parts.recipe is not None and app.app.parts.recipe.name == "rotor-a"
