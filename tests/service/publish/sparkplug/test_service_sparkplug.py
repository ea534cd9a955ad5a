"""The Sparkplug B edge node against a real Mosquitto and a host application decoding with pysparkplug."""

from __future__ import annotations

import functools
import logging
import time
from datetime import UTC, datetime

import pytest

from service.persistence.store import Store
from service.publish.replies import CommandReply
from service.publish.sparkplug import metrics as M
from service.publish.sparkplug.node import BDSEQ_FILE, SparkplugNode
from service.publish.sparkplug.settings import SparkplugSettings
from tests.service.conftest import wait_until
from tests.service.publish.sparkplug.sparkplug_host import SparkplugHost, ps
from tests.service.publish.sparkplug.tahu import require_tahu, tahu_decode

pytestmark = pytest.mark.broker

DT = ps.DataType


def settings(port: int, **kw) -> SparkplugSettings:
    return SparkplugSettings(host="127.0.0.1", port=port, reconnect_min=0.1, reconnect_max=0.5, keepalive=5, **kw)


def result_payload(uuid: str, seq: int, *, i: int, finished: float) -> dict:
    """A published result payload (the keys the Sparkplug metrics read)."""
    return {"uuid": uuid, "seq": seq, "J": 0.01 * (i + 1), "J_U": 2e-5, "J_std": 1e-5, "omega_n": 5.4,
            "damping_ratio": 0.003, "flags": ["drift_corrected"], "flag_bits": 4, "timestamp": finished,
            "trigger": "test", "part_id": f"SN-{i}", "verdict": "OK"}


def add_results(store: Store, n: int, start: int = 0) -> list[str]:
    """n results stored with their Sparkplug outbox rows, finished now (after any birth so far)."""
    now = time.time()
    return [store.record(status="ok", trigger="test", device_id="rig1", software_version="0", started_at=1.0,
                         finished_at=2.0, result={"J": 0.01 * (i + 1)},
                         build_payload=functools.partial(result_payload, i=i, finished=now + 1e-3 * i),
                         enqueue={"sparkplug": ("result",)}).uuid
            for i in range(start, start + n)]


@pytest.fixture
def host(broker):
    h = SparkplugHost(broker.port)
    h.online()
    yield h
    h.close()


@pytest.fixture
def node_factory(tmp_path):
    made: list[tuple[SparkplugNode, Store]] = []

    def make(port: int, state=None, on_command=None, **kw) -> SparkplugNode:
        store = Store(state or tmp_path / "state")
        node = SparkplugNode(settings(port, **kw), "rig1", store, software_version="9.9", on_command=on_command)
        node.start()
        made.append((node, store))
        return node

    yield make
    for node, store in made:
        node.stop()
        store.close()


def bdseq_of_death(death) -> int:
    m = death.decoded.bd_seq_metric
    assert m.name == "bdSeq" and m.datatype == DT.INT64
    return m.value


def _births(h: SparkplugHost, n: int = 1) -> bool:
    return h.count("NBIRTH") >= n and h.count("DBIRTH") >= n


def test_the_host_decodes_the_births_every_metric_typed_with_its_unit_and_a_result(broker, host, node_factory):
    node = node_factory(broker.port, primary_host="scada")
    host.wait(_births, 10, "NBIRTH and DBIRTH")
    [nb] = host.of("NBIRTH")
    assert nb.topic == "spBv1.0/moi/NBIRTH/rig1" and nb.decoded.seq == 0
    node_metrics = {m.name: m for m in nb.decoded.metrics}
    assert node_metrics["bdSeq"].datatype == DT.INT64 and node_metrics["bdSeq"].value == node._bdseq
    assert node_metrics["Node Control/Rebirth"].datatype == DT.BOOLEAN and node_metrics["Node Control/Rebirth"].value is False
    [db] = host.of("DBIRTH")
    assert db.topic == "spBv1.0/moi/DBIRTH/rig1/rig1" and db.decoded.seq == 1
    births = {m.name: m for m in db.decoded.metrics}
    assert set(births) == {m.name for m in M.DEVICE}
    units = {m.name: dict(zip(m.properties.keys, (v.string_value for v in m.properties.values))).get("engUnit")
             for m in db.wire.metrics}
    for spec in M.DEVICE:
        assert births[spec.name].datatype == DT(int(spec.datatype)), spec.name
        assert births[spec.name].alias == M.ALIAS[spec.name]
        assert units[spec.name] == spec.unit, spec.name
    assert units["Result/J"] == "kg·m²" and units["Result/omega_n"] == "rad/s"
    assert len({m.alias for m in db.decoded.metrics} | {M.ALIAS[M.REBIRTH]}) == len(M.DEVICE) + 1  # unique aliases

    [uuid] = add_results(node.sender.store, 1)
    node.wake()
    [r] = host.wait(lambda h: h.results(), 10, "the result DDATA")
    assert r["Result/UUID"] == uuid and r["Result/J"] == pytest.approx(0.01) and r["Result/J_U"] == 2e-5
    assert (r["Result/omega_n"], r["Result/damping_ratio"]) == (5.4, 0.003)
    assert (r["Result/Flags"], r["Result/Flag Bits"], r["Result/Verdict"], r["Result/Part ID"]) == \
        ("drift_corrected", 4, "OK", "SN-0")
    stored = node.sender.store.get(uuid)
    assert abs(r["Result/Finished"] - datetime.fromtimestamp(stored.payload["timestamp"], UTC)).total_seconds() < 1e-3
    assert r["_seq"] == 2 and not r["_historical"]  # finished after the birth: live, not historical
    [ddata] = host.of("DDATA")
    assert all(not m.HasField("name") and m.HasField("alias") for m in ddata.wire.metrics)  # by alias only
    wait_until(lambda: node.sender.store.outbox_count("sparkplug") == 0, 10, what="the acknowledged row to go")
    assert host.errors == []


def test_a_rebirth_request_is_honoured_with_the_same_bdseq_and_seq_from_zero(broker, host, node_factory):
    node = node_factory(broker.port)
    host.wait(_births, 10, "the first births")
    host.command("rig1", None, [("Node Control/Rebirth", DT.BOOLEAN, True)])
    host.wait(lambda h: _births(h, 2), 10, "the births again")
    first, again = host.of("NBIRTH")
    bd = [{m.name: m.value for m in b.decoded.metrics}["bdSeq"] for b in (first, again)]
    assert bd[0] == bd[1] == node._bdseq and again.decoded.seq == 0 and host.of("DBIRTH")[1].decoded.seq == 1


def test_results_wait_while_the_primary_host_is_offline_and_arrive_once_in_order(broker, host, node_factory):
    node = node_factory(broker.port, primary_host="scada")
    host.wait(_births, 10, "births while the host is online")
    bd0 = node._bdseq
    host.online(False)
    # the node leaves: NDEATH with its bdSeq, then a new session waits for the host
    [death] = host.wait(lambda h: h.of("NDEATH"), 10, "NDEATH when the host went offline")
    assert bdseq_of_death(death) == bd0
    wait_until(lambda: node.connected_event.is_set() and node._bdseq == bd0 + 1 and not node.born_event.is_set(),
               10, what="the node reconnected, waiting for the host")
    uuids = add_results(node.sender.store, 4)
    node.wake()
    assert node.sender.store.outbox_count("sparkplug") == 4
    assert host.results() == [] and host.count("NBIRTH") == 1
    host.online(True)
    host.wait(lambda h: len(h.results()) >= 4, 10, "the held results")
    births = host.of("NBIRTH")
    assert len(births) == 2 and {m.name: m.value for m in births[1].decoded.metrics}["bdSeq"] == bd0 + 1
    wait_until(lambda: node.sender.store.outbox_count("sparkplug") == 0, 10, what="the acknowledged rows to go")
    got = host.results()
    assert [r["Result/UUID"] for r in got] == uuids  # in order, once
    assert [r["_seq"] for r in got] == [2, 3, 4, 5] and all(r["_historical"] for r in got)


def test_across_a_broker_restart_the_next_session_has_the_next_bdseq_and_nothing_is_lost(tmp_path, persistent_broker,
                                                                                       node_factory):
    host = SparkplugHost(persistent_broker.port, persistent=True)
    try:
        node = node_factory(persistent_broker.port)
        host.wait(_births, 10, "births")
        bd0 = node._bdseq
        persistent_broker.stop()
        wait_until(lambda: not node.connected_event.is_set(), 10, what="the node to see the broker gone")
        uuids = add_results(node.sender.store, 3)
        node.wake()
        persistent_broker.start()
        host.wait(lambda h: len({r["Result/UUID"] for r in h.results()}) == 3, 20, "the results after the restart")
        assert [r["Result/UUID"] for r in host.results()] == uuids  # the host's session kept them queued
        # the new session's birth (asked for again: the host may have been resubscribing when it came)
        births = host.count("NBIRTH")
        host.command("rig1", None, [("Node Control/Rebirth", DT.BOOLEAN, True)])
        host.wait(lambda h: h.count("NBIRTH") > births, 10, "the rebirth")
        nb = host.of("NBIRTH")[-1]
        assert {m.name: m.value for m in nb.decoded.metrics}["bdSeq"] == bd0 + 1 and nb.decoded.seq == 0
        node.stop()
        # a restarted node goes on counting: bdSeq is kept in the state directory
        assert int((tmp_path / "state" / BDSEQ_FILE).read_text()) == bd0 + 1
        again = node_factory(persistent_broker.port)
        assert again._bdseq == bd0 + 2
    finally:
        host.close()


def test_the_will_is_the_ndeath_of_the_session_the_birth_announced(broker, host, node_factory):
    node = node_factory(broker.port)
    host.wait(_births, 10, "births")
    node.client.socket().close()  # the connection drops without a DISCONNECT: the broker sends the will
    [death] = host.wait(lambda h: h.of("NDEATH"), 15, "the will")
    birth = {m.name: m.value for m in host.of("NBIRTH")[0].decoded.metrics}
    assert bdseq_of_death(death) == birth["bdSeq"]
    host.wait(lambda h: _births(h, 2), 15, "the births of the next session")
    assert {m.name: m.value for m in host.of("NBIRTH")[1].decoded.metrics}["bdSeq"] == (birth["bdSeq"] + 1) % 256


def test_commands_are_answered_as_on_mqtt_and_malformed_ones_never_stop_the_node(broker, host, node_factory):
    calls = []

    def on_command(name, source, data=None, reply=None):
        calls.append((name, source, data))
        reply(CommandReply(name, "done"))

    node = node_factory(broker.port, on_command=on_command)
    host.wait(_births, 10, "births")
    host.send("rig1", "rig1", b"\xff\xfe not protobuf")
    host.send("rig1", None, b"\x0a\xff\xff")                       # a truncated NCMD: logged, ignored
    host.command("rig1", "rig1", [("Command/Launch", DT.BOOLEAN, True)])
    host.command("rig1", "rig1", [("Command/Part ID", DT.INT32, 5)])  # a number where the ID is a string
    host.command("rig1", "rig1", [("Command/Part ID", DT.STRING, "SN-42"), ("Command/Measure", DT.BOOLEAN, True)])
    host.command("rig1", None, [("Node Control/Rebirth", DT.STRING, "yes")])  # not a boolean: ignored
    replies = host.wait(lambda h: len(h.replies()) >= 5 and h.replies(), 10, "five replies")
    assert [(r["command"], r["status"], r["reason"]) for r in replies] == [
        ("unknown", "refused", "malformed"), ("Command/Launch", "refused", "unknown_command"),
        ("part_id", "refused", "malformed"), ("part_id", "done", None), ("trigger", "done", None)]
    assert calls == [("part_id", "sparkplug", {"part_id": "SN-42"}), ("trigger", "sparkplug", None)]
    host.command("rig1", None, [("Node Control/Rebirth", DT.BOOLEAN, True)])
    host.wait(lambda h: _births(h, 2), 10, "a rebirth after the malformed commands")
    assert host.count("NBIRTH") == 2 and node.callback_errors == 0 and node.failure() is None


def test_seq_runs_0_to_255_and_wraps(broker, host, node_factory):
    node = node_factory(broker.port, window=50)
    host.wait(_births, 10, "births")
    add_results(node.sender.store, 260)  # with the two births: past 255
    node.wake()
    host.wait(lambda h: len(h.results()) >= 260, 30, "260 results")
    seqs = [r.decoded.seq for r in host.received if r.kind in ("NBIRTH", "DBIRTH", "DDATA")]
    assert seqs == [i % 256 for i in range(len(seqs))]


def test_a_daemon_delivers_every_result_once_across_a_sigkill_a_broker_restart_and_a_host_away(tmp_path,
                                                                                             persistent_broker):
    """`moi run` with [sparkplug]: a measurement asked for by DCMD, one measured while the primary host is
    away, the daemon then killed (SIGKILL) and the broker restarted: the host gets both, once each, in order."""
    from tests.service.conftest import appliance_doc, free_port, port_open, write_toml
    from tests.service.test_service_process import start_daemon, trigger_and_wait

    state, mb_port = tmp_path / "state", free_port()
    cfg = write_toml(tmp_path / "appliance.toml", appliance_doc(state, modbus_port=mb_port, sparkplug={
        "host": "127.0.0.1", "port": persistent_broker.port, "primary_host": "scada", "reconnect_min": 0.1,
        "reconnect_max": 0.5, "keepalive": 5}))
    host = SparkplugHost(persistent_broker.port, persistent=True)
    host.online()
    daemon = start_daemon(cfg)
    try:
        host.wait(_births, 60, "the daemon's births")
        host.command("test-rig", "test-rig", [("Command/Measure", DT.BOOLEAN, True)])
        host.wait(lambda h: h.results(), 60, "the result of the DCMD measurement")
        assert [(r["command"], r["status"]) for r in host.replies()][-1] == ("trigger", "done")
        host.online(False)
        host.wait(lambda h: h.of("NDEATH"), 10, "NDEATH when the host left")
        trigger_and_wait(mb_port, 2)
    finally:
        daemon.kill()
        daemon.communicate(timeout=10)
    with Store(state, read_only=True) as store:
        stored = [m.uuid for m in reversed(store.list())]
        assert len(stored) == 2 and store.outbox_count("sparkplug") == 1
    assert len(host.results()) == 1
    persistent_broker.stop()
    persistent_broker.start()
    daemon = start_daemon(cfg)
    try:
        wait_until(lambda: port_open(mb_port) or daemon.poll() is not None, 30, what="the restarted daemon")
        host.online(True)
        host.wait(lambda h: len(h.results()) >= 2, 60, "the held result")
        got = host.results()
        assert [r["Result/UUID"] for r in got] == stored and [r["_historical"] for r in got] == [False, True]
        assert all(r["_device"] == "test-rig" for r in got) and host.errors == []
    finally:
        daemon.kill()
        daemon.communicate(timeout=10)
        host.close()


def test_no_state_payload_stops_the_births_or_leaves_a_traceback(broker, host, node_factory, caplog):
    """Any broker client can publish the primary host's STATE: a spoofed one stamped far ahead (1e30, an hour),
    Infinity, NaN or garbage is refused and logged; the node stays born and follows the genuine host after it."""
    caplog.set_level(logging.INFO, logger="moi.sparkplug")
    node = node_factory(broker.port, primary_host="scada")
    host.wait(_births, 10, "births while the host is online")
    ahead = int(time.time() * 1000) + 3_600_000
    spoofs = [b'{"online": false, "timestamp": 1e30}', b'{"online": true, "timestamp": 1e30}',
              b'{"online": false, "timestamp": Infinity}', b'{"online": false, "timestamp": NaN}',
              f'{{"online": false, "timestamp": {ahead}}}'.encode(), b"\xff garbage", b"[false, 1]", b'"OFFLINE"',
              b'{"online": false, "timestamp": 1' + b"0" * 400 + b"}"]
    for raw in spoofs:
        host.client.publish(host.state_topic, raw, qos=1).wait_for_publish(5)
    wait_until(lambda: node.states_refused == len(spoofs), 10, what="every spoofed STATE refused")
    assert node.born_event.is_set() and host.count("NDEATH") == 0 and host.count("NBIRTH") == 1
    host.online(False)  # the genuine host, stamped now: acted on
    host.wait(lambda h: h.of("NDEATH"), 10, "NDEATH when the genuine host went offline")
    host.online(True)
    host.wait(lambda h: _births(h, 2), 10, "the births when the genuine host came back")
    assert node.callback_errors == 0 and node.last_error is None and node.health()["states_refused"] == len(spoofs)
    assert not any(r.exc_info for r in caplog.records) and "Traceback" not in caplog.text
    refused = [r.getMessage() for r in caplog.records if "STATE of scada refused" in r.getMessage()]
    assert len(refused) == 1 and "centuries ahead of this clock" in refused[0]  # logged once (a minute), not 9 times


def test_a_flood_of_rebirth_requests_gives_one_birth_per_interval_and_answers_the_last(broker, host, node_factory):
    interval = 1.0
    node = node_factory(broker.port, rebirth_interval=interval)
    host.wait(_births, 10, "the first births")
    n, start = 300, time.monotonic()
    rebirth = [("Node Control/Rebirth", DT.BOOLEAN, True)]
    for _ in range(n):
        host.command("rig1", None, rebirth)

    def settled() -> bool:
        with node._lock:
            return node._limit.requests == n and node._limit.due_in() is None

    wait_until(settled, 30, what="every request read and its birth sent")
    elapsed = time.monotonic() - start
    host.wait(lambda h: h.count("NBIRTH") == h.count("DBIRTH") == node.births, 10, "the births sent")
    extra = node.births - 1
    assert 1 <= extra <= 2 + elapsed / interval, (extra, elapsed)  # answered; one per interval at most, not 300
    assert node._limit.deferred >= n - extra
    assert (node.health()["births"], node.health()["rebirth_requests"]) == (node.births, n)
    seqs = [r.decoded.seq for r in host.received if r.kind in ("NBIRTH", "DBIRTH")]
    assert seqs == [0, 1] * node.births and host.errors == []


def test_tahus_javascript_codec_reads_every_metric_of_the_births_and_of_a_result(broker, host, node_factory):
    """What a Node.js host decodes (Eclipse Tahu's sparkplug-payload): every birth metric with its type, alias and
    unit, and every value of a result's DDATA, the 32 flag bits among them, read by the birth's aliases."""
    require_tahu()
    node = node_factory(broker.port)
    host.wait(_births, 10, "births")
    now, bits = time.time(), (1 << 31) | (1 << 13) | 4
    store = node.sender.store
    uuid = store.record(status="ok", trigger="test", device_id="rig1", software_version="0", started_at=1.0,
                        finished_at=2.0, result={"J": 0.0125},
                        build_payload=lambda uuid, seq: result_payload(uuid, seq, i=0, finished=now) | {"flag_bits": bits},
                        enqueue={"sparkplug": ("result",)}).uuid
    node.wake()
    host.wait(lambda h: h.results(), 10, "the result")
    wanted = [host.of("NBIRTH")[0], host.of("DBIRTH")[0], *host.of("DDATA")]
    nbirth, dbirth, *data = tahu_decode([(r.topic, r.raw) for r in wanted])
    assert all("error" not in d for d in (nbirth, dbirth, *data)), (nbirth, dbirth, data)

    assert (nbirth["seq"], dbirth["seq"]) == ("0", "1")
    node_metrics = {m["name"]: m for m in nbirth["metrics"]}
    assert (node_metrics["bdSeq"]["type"], int(node_metrics["bdSeq"]["value"])) == ("Int64", node._bdseq)
    assert (node_metrics[M.REBIRTH]["type"], node_metrics[M.REBIRTH]["value"]) == ("Boolean", False)
    assert node_metrics[M.SOFTWARE_VERSION]["value"] == "9.9"
    births = {m["name"]: m for m in dbirth["metrics"]}
    assert set(births) == {m.name for m in M.DEVICE}
    for spec in M.DEVICE:
        b = births[spec.name]
        assert b["type"] == spec.datatype.name and int(b["alias"]) == M.ALIAS[spec.name], b
        assert (b.get("properties") or {}).get("engUnit", {}).get("value") == spec.unit, b

    by_alias = {int(m["alias"]): m["name"] for m in dbirth["metrics"]}
    [result] = [d for d in data if any(by_alias[int(m["alias"])] == "Result/UUID" for m in d["metrics"])]
    values = {by_alias[int(m["alias"])]: m for m in result["metrics"]}
    assert set(values) == {m.name for m in M.RESULT}
    assert all(m["type"] == births[name]["type"] for name, m in values.items())  # typed in the data message too
    assert values["Result/UUID"]["value"] == uuid and values["Result/J"]["value"] == pytest.approx(0.01)
    assert int(values["Result/Flag Bits"]["value"]) == bits  # all 32 bits, where Tahu's codec reads them
    assert int(values["Result/Finished"]["value"]) == round(now * 1000)
    assert values["Result/Flags"]["value"] == "drift_corrected" and values["Result/Part ID"]["value"] == "SN-0"
    assert (values["Result/omega_n"]["value"], values["Result/damping_ratio"]["value"]) == (5.4, 0.003)
    assert int(values["Result/Sequence"]["value"]) == store.get(uuid).seq

    node.stop()  # a clean stop publishes NDEATH with the session's bdSeq
    [death] = host.wait(lambda h: h.of("NDEATH"), 10, "NDEATH")
    [ndeath] = tahu_decode([(death.topic, death.raw)])
    assert [(m["name"], m["type"], int(m["value"])) for m in ndeath["metrics"]] == [("bdSeq", "Int64", node._bdseq)]
