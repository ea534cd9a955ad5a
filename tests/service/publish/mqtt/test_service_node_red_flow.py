"""examples/node-red/moi-results-flow.json: a Node-RED flow an integrator imports to read the results over MQTT.
Its nodes and wires hold together, its topics are the appliance's (the code's topic table, for the device id of
examples/appliance-sim.toml), its command is not retained, and its JavaScript runs in Node.js on a real result."""

from __future__ import annotations

import json
import shutil
import subprocess
import tomllib

from service.publish.mqtt.topics import Topics
from service.publish.payload import result_payload
from tests.components import missing
from tests.service.conftest import REPO

FLOW = REPO / "examples" / "node-red" / "moi-results-flow.json"


def flow() -> list[dict]:
    return json.loads(FLOW.read_text(encoding="utf-8"))


def test_the_flows_nodes_are_wired_to_nodes_it_has_and_use_its_broker():
    nodes = flow()
    ids = [n["id"] for n in nodes]
    assert len(ids) == len(set(ids))
    by_id = {n["id"]: n for n in nodes}
    [tab] = [n for n in nodes if n["type"] == "tab"]
    for n in nodes:
        for output in n.get("wires", []):
            assert all(target in by_id and by_id[target].get("z") == tab["id"] for target in output), n["id"]
        if n["type"] in ("mqtt in", "mqtt out"):
            assert by_id[n["broker"]]["type"] == "mqtt-broker"
    kinds = {n["type"] for n in nodes}
    assert {"mqtt in", "mqtt out", "function", "debug", "inject", "mqtt-broker"} <= kinds


def test_the_flows_topics_are_in_the_appliances_topic_table():
    device = tomllib.loads((REPO / "examples" / "appliance-sim.toml").read_text(encoding="utf-8"))["device"]["id"]
    topics = Topics("moi", device)
    table = {v for k, v in vars(topics).items() if isinstance(v, str) and k != "base"}
    used = {n["topic"]: n for n in flow() if n["type"] in ("mqtt in", "mqtt out")}
    assert set(used) <= table, set(used) - table
    assert {topics.result, topics.state, topics.reply, topics.cmd_measure} == set(used)
    out = used[topics.cmd_measure]
    assert out["type"] == "mqtt out" and out["retain"] == "false" and out["qos"] == "1"  # as docs/service.md advises
    assert used[topics.result]["qos"] == "1" and used[topics.result]["datatype"] == "json"


def test_the_flows_functions_run_on_a_real_result_once_per_uuid():
    node = shutil.which("node") or shutil.which("nodejs")
    if node is None:
        missing("Node.js not found (Debian package nodejs)")
    funcs = {n["name"]: n["func"] for n in flow() if n["type"] == "function"}
    result = result_payload({"J": 0.0125, "J_U": 2.3e-5, "J_std": 7.7e-9, "flags": ["drift_corrected"]},
                            uuid="ef6ecdb1-d4bf-4e81-816e-55598355be01", seq=1, device_id="sim-01", trigger="mqtt",
                            started_at=1.0, finished_at=3.0, software_version="0")
    script = f"const funcs = {json.dumps(funcs)}, result = {json.dumps(result)};" + """
const store = {};
const context = {get: (k) => store[k], set: (k, v) => { store[k] = v; }};
const run = (name, msg) => new Function("msg", "context", "node", funcs[name])(msg, context, {});
const first = run("once per uuid: J ± U", {payload: result});
const again = run("once per uuid: J ± U", {payload: JSON.parse(JSON.stringify(result))});
const command = run("command with an id", {payload: 1});
process.stdout.write(JSON.stringify({first: first.payload, again, command: command.payload}));
"""
    done = subprocess.run([node, "-e", script], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout)
    assert out["first"]["J"] == 0.0125 and out["first"]["J_U"] == 2.3e-5 and out["first"]["unit"] == "kg·m²"
    assert out["first"]["uuid"] == result["uuid"] and out["first"]["flags"] == ["drift_corrected"]
    assert out["again"] is None  # a second delivery of the same result is dropped
    assert out["command"]["id"].startswith("node-red-")
