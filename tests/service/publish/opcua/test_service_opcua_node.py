"""The daemon's OPC UA server read by node-opcua, an OPC UA stack independent of the server's (asyncua), as an
integrator's client would (tests/node/opcua/client.js, run by Node.js): it logs in over Basic256Sha256 Sign &
Encrypt, browses, subscribes to ResultReadyEventType, calls the Result Transfer methods and decodes every
structure from the DataTypeDefinitions the server publishes. The client prints what it decoded as JSON; these
tests hold it against the stored result. node-opcua comes from the npm registry (`make node`, the versions
in tests/node/opcua/package-lock.json); under CI a missing client fails the run."""

from __future__ import annotations

import json
import queue
import shutil
import subprocess
import threading
import time
from typing import Any

import pytest

from service.publish.opcua.model import CONTENT_FIELDS, UNECE_URI, UNITS
from tests.components import missing
from tests.service.conftest import REPO, RunningAppliance, appliance_doc

USER, PASSWORD = "line-7", "s3cret"
CLIENT_DIR = REPO / "tests" / "node" / "opcua"
NODE = shutil.which("node") or shutil.which("nodejs")
#: the client's whole run is bounded by its own timer (120 s); this bounds it from outside
DEADLINE_S = 150.0


def _need_node_opcua() -> str:
    if NODE is None:
        what = "Node.js (the Debian package nodejs)"
    elif not (CLIENT_DIR / "node_modules" / "node-opcua-client").is_dir():
        what = "node-opcua (`make node`: npm ci in tests/node/opcua)"
    else:
        return NODE
    missing(f"{what} is not installed")


class _NodeClient:
    """client.js in a child process; its stdout lines read by a thread (node-opcua also writes its own notices
    there), so that every wait has a deadline."""

    def __init__(self, node: str, endpoint: str, pki: str) -> None:
        self.proc = subprocess.Popen([node, "client.js", endpoint, USER, PASSWORD, pki, "test-rig"], cwd=CLIENT_DIR,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.deadline = time.monotonic() + DEADLINE_S
        self.stderr = ""
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put(None)

    def until(self, wanted: str) -> dict[str, Any] | None:
        """Wait for the line ``wanted`` (None) or for the JSON document (returned; the client ends with it)."""
        while True:
            left = self.deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"node-opcua client: no {wanted or 'result'} within {DEADLINE_S:g} s")
            line = self.lines.get(timeout=left)
            if line is None:
                raise AssertionError(f"node-opcua client ended without a result: {self._stderr()}")
            if line.startswith("{"):
                return json.loads(line)
            if line == wanted:
                return None

    def _stderr(self) -> str:
        self.close()
        return self.stderr[-2000:]

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        _, self.stderr = self.proc.communicate(timeout=10)


@pytest.fixture(scope="module")
def decoded(tmp_path_factory):
    """What node-opcua decoded of one measurement, and the appliance that made it."""
    node = _need_node_opcua()
    base = tmp_path_factory.mktemp("opcua-node")
    pw = base / "opcua-password"
    pw.write_text(PASSWORD + "\n", encoding="utf-8")
    app = RunningAppliance(appliance_doc(base / "state", opcua={
        "host": "127.0.0.1", "port": 0, "username": USER, "password_file": str(pw)}))
    try:
        client = _NodeClient(node, app.app.opcua.endpoint, str(base / "pki"))
        try:
            early = client.until("subscribed")
            assert early is None, f"node-opcua client failed before subscribing: {early}"
            app.press()
            doc = client.until("")
        finally:
            client.close()
        assert doc is not None and "error" not in doc, doc
        app.wait_done(1)
        yield doc, app
    finally:
        app.stop()


def _content(result: dict) -> dict:
    """ResultContent's one InertiaResultDataType, as node-opcua decoded it (a Variant holding it)."""
    (variant,) = result["resultContent"]
    assert variant["dataType"] == "ExtensionObject"
    return variant["value"]


def test_node_opcua_decodes_the_event_latest_result_and_the_methods_outputs(decoded):
    doc, app = decoded
    uuid = app.app.stored[0]
    stored = app.app.store.get(uuid)
    event = doc["event"]
    assert event["eventType"].endswith(";s=InertiaResultReadyEventType") and event["severity"] == 100
    latest, by_latest, by_id = (doc["latestResult"]["value"], doc["getLatestResult"]["outputs"],
                                doc["getResultById"]["outputs"])
    assert doc["getLatestResult"]["status"] == doc["getResultById"]["status"] == "Good"
    assert by_latest[0] == by_id[0] == 0 and by_latest[2] == by_id[2] == 0  # ResultHandle, Error
    for result in (event["result"], latest, by_latest[1], by_id[1]):
        meta, content = result["resultMetaData"], _content(result)
        assert meta["resultId"] == uuid and meta["isSimulated"] is True and meta["resultState"] == 1
        assert meta["resultEvaluation"] == 0  # Undefined: no recipe
        assert meta["processingTimes"]["startTime"] <= meta["processingTimes"]["endTime"]
        assert content["sequenceNumber"] == stored.seq
        assert content["j"] == pytest.approx(stored.payload["J"], rel=1e-12)
        assert content["omega_n"] == pytest.approx(stored.payload["omega_n"], rel=1e-12)
    # the ResultContent variable: the same InertiaResultDataType
    assert doc["contentVariable"][0]["j"] == pytest.approx(stored.payload["J"], rel=1e-12)
    assert doc["getUnknownResult"] == {"status": "BadNotFound", "outputs": []}
    assert doc["acknowledgeResults"] == {"status": "Good", "outputs": [[], 0]}


def test_node_opcua_finds_the_specifications_types(decoded):
    doc, _ = decoded
    r = doc["namespaces"]["result"]
    result_type = f"ns={r};i=2001"
    assert doc["latestResult"]["typeDefinition"] == [result_type]
    assert doc["latestResult"]["dataType"] == f"ns={r};i=3008"
    # the type a browse of the Results folder reports (a client finding results by type reads this one)
    assert {c["name"]: c["typeDefinition"] for c in doc["results"]}["LatestResult"] == result_type
    assert doc["eventResultTypeDefinition"] == [result_type]  # ResultReadyEventType's Result
    data_type_encoding_type = ["ns=0;i=76"]
    assert doc["encodings"] == {"ResultDataType": {"Default Binary": data_type_encoding_type},
                                "InertiaResultDataType": {"Default Binary": data_type_encoding_type}}
    m = doc["namespaces"]["machinery"]
    states = {s["name"]: s["typeDefinition"] for s in doc["itemStates"] if s["name"] != "CurrentState"}
    assert states == dict.fromkeys(("NotAvailable", "OutOfService", "NotExecuting", "Executing"), "ns=0;i=2307")
    assert {b["name"]: b["typeDefinition"] for b in doc["buildingBlocks"]} == {
        "Identification": f"ns={m};i=1012", "MachineryItemState": f"ns={m};i=1002",
        "MachineryOperationMode": f"ns={m};i=1008", "ResultManagement": f"ns={r};i=1004"}


def test_every_physical_value_carries_its_unece_unit(decoded):
    doc, _ = decoded
    components = doc["components"]
    with_units = {name for name, c in components.items() if "engineeringUnits" in c}
    assert with_units == {name for name, *_, unit in CONTENT_FIELDS if unit is not None}
    expected = {"J": "B32", "J_U": "B32", "J_u": "B32", "U": "B32", "omega_n": "2A", "damping_ratio": "C62"}
    for name, code in expected.items():
        eu = components[name]["engineeringUnits"]
        # OPC 10000-8: the UNECE common code, one byte per character, as UnitId ('B32' → 0x423332)
        assert eu["unitId"] == int.from_bytes(code.encode("ascii"), "big"), name
        assert eu["namespaceUri"] == UNECE_URI == "http://www.opcfoundation.org/UA/units/un/cefact"
        assert UNITS[eu["displayName"]["text"]][0] == code
        assert components[name]["typeDefinition"] == "ns=0;i=17497"  # AnalogUnitType
    assert components["J"]["value"] == pytest.approx(doc["latestResult"]["value"]["resultContent"][0]["value"]["j"])
