"""The result store, its outbox, and `moi results` / `moi export`."""

from __future__ import annotations

import csv
import io
import json
import sqlite3

import numpy as np
import pytest

from measurement import Pendulum, Rig, identify, simulate_trace
from service.cli import main
from service.persistence.canonical import dumps
from service.persistence.store import Store
from service.persistence.tables import SCHEMA_VERSION
from service.publish.payload import result_payload


@pytest.fixture(scope="module")
def result():
    rig = Rig(kind="torsion", stiffness=0.3651, tare_inertia=4.5043e-3, declared=("viscous",))
    trace = simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}}), theta0=0.25, duration=5, rate=100,
                           noise_std=1e-4, seed=3)
    return identify(trace, rig), trace, rig


MQTT_RESULT = {"mqtt": ("result",)}  # the outbox rows MQTT queues with each result


def store_one(store: Store, result, status: str = "ok", enqueue=MQTT_RESULT, t0: float = 1_700_000_000.0):
    res, trace, rig = result
    d = res.to_dict()

    def build(uuid, seq):
        return result_payload(d, uuid=uuid, seq=seq, device_id="dev", trigger="button", started_at=t0,
                              finished_at=t0 + 6.5, software_version="9.9")

    return store.record(status=status, trigger="button", device_id="dev", software_version="9.9", started_at=t0,
                        finished_at=t0 + 6.5, result=d if status == "ok" else None,
                        build_payload=build if status == "ok" else None, error=None if status == "ok" else "encoder fault",
                        rig=rig.to_dict(), config={"x": 1}, trace_t=trace.t, trace_angle=trace.angle,
                        trace_meta={"encoder": {"samples": len(trace)}}, enqueue=enqueue)


def test_a_measurement_is_stored_with_trace_payload_rig_config_and_an_outbox_row(tmp_path, result):
    with Store(tmp_path) as store:
        m = store_one(store, result)
        assert m.seq == 1 and m.status == "ok"
        full = store.get(m.uuid, trace=True)
        assert full.payload["uuid"] == m.uuid and full.payload["seq"] == 1
        assert full.payload["J"] == result[0].to_dict()["J"]  # the payload carries the result unchanged
        assert full.payload["residual_rms_before"] == result[0].baseline.residual_rms
        assert full.rig["rig"]["kind"] == "torsion" and full.config == {"x": 1}
        np.testing.assert_array_equal(full.trace_t, result[1].t)
        np.testing.assert_array_equal(full.trace_angle, result[1].angle)
        [item] = store.outbox_pending()
        assert item.uuid == m.uuid and item.payload == dumps(full.payload)
        assert store.get(str(m.seq)).uuid == m.uuid and store.get(m.uuid[:8]).uuid == m.uuid


def test_the_database_is_in_wal_mode(tmp_path, result):
    Store(tmp_path).close()
    with sqlite3.connect(tmp_path / "results.db") as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_ack_removes_the_row_and_marks_the_measurement_published(tmp_path, result):
    with Store(tmp_path) as store:
        m = store_one(store, result)
        [item] = store.outbox_pending()
        assert store.outbox_ack(item.id) is True
        assert store.outbox_ack(item.id) is False  # a duplicate PUBACK is harmless
        assert store.outbox_count() == 0
        assert store.get(m.uuid).published_at is not None


def test_sequence_numbers_survive_a_reopen_and_failures_take_a_number(tmp_path, result):
    with Store(tmp_path) as store:
        a = store_one(store, result)
        b = store_one(store, result, status="failed")
        assert store.outbox_count() == 1  # a failed measurement publishes nothing
    with Store(tmp_path) as store:
        c = store_one(store, result)
        assert (a.seq, b.seq, c.seq) == (1, 2, 3)
        assert [m.seq for m in store.list()] == [3, 2, 1]
        assert store.latest().uuid == c.uuid
        assert store.list(status="failed")[0].error == "encoder fault"
        assert [i.uuid for i in store.outbox_pending()] == [a.uuid, c.uuid]  # oldest first


def test_results_command_lists_and_shows(tmp_path, result, capsys):
    with Store(tmp_path) as store:
        m = store_one(store, result)
        store_one(store, result, status="failed")
    assert main(["results", "--state-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert m.uuid[:8] in out and "failed" in out and "encoder fault" in out
    assert main(["results", "1", "--state-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert m.uuid in out and "J" in out and "kg·m²" in out
    assert main(["results", "--state-dir", str(tmp_path), "--json", "--status", "ok"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [r["uuid"] for r in listed] == [m.uuid]


def test_results_without_a_store_is_one_clear_line(tmp_path, capsys):
    assert main(["results", "--state-dir", str(tmp_path / "nothing")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no result store found" in err


def test_export_csv_json_and_trace(tmp_path, result, capsys):
    with Store(tmp_path) as store:
        m = store_one(store, result)
        store_one(store, result, status="failed")
    out_csv = tmp_path / "all.csv"
    assert main(["export", "--state-dir", str(tmp_path), "--out", str(out_csv)]) == 0
    rows = list(csv.DictReader(io.StringIO(out_csv.read_text())))
    assert [r["status"] for r in rows] == ["ok", "failed"]  # oldest first
    assert float(rows[0]["J"]) == result[0].J and rows[0]["uuid"] == m.uuid
    assert rows[1]["error"] == "encoder fault" and rows[1]["J"] == ""
    assert main(["export", "--state-dir", str(tmp_path), "--format", "json", "--status", "ok"]) == 0
    docs = json.loads(capsys.readouterr().out)
    assert docs[0]["payload"]["uuid"] == m.uuid and docs[0]["payload"]["J"] == result[0].J
    trace_csv = tmp_path / "trace.csv"
    assert main(["export", "--state-dir", str(tmp_path), "--trace", m.uuid, "--out", str(trace_csv)]) == 0
    from service.sources.files import read_trace
    t = read_trace(trace_csv)
    np.testing.assert_allclose(t.t, result[1].t, atol=1e-9)
    np.testing.assert_allclose(t.angle, result[1].angle, rtol=1e-11, atol=1e-15)


def test_a_uuid_that_starts_with_digits_is_found_by_its_prefix(tmp_path, result, monkeypatch):
    import uuid as uuidlib

    import service.persistence.store as store_module

    fixed = uuidlib.UUID("12345678-9abc-4def-8123-456789abcdef")
    monkeypatch.setattr(store_module.uuidlib, "uuid4", lambda: fixed)
    with Store(tmp_path) as store:
        m = store_one(store, result)
        assert m.uuid == str(fixed) and m.seq == 1
        assert store.get("12345678").uuid == m.uuid   # no measurement 12345678: the UUID prefix
        assert store.get("1").uuid == m.uuid          # digits that are a sequence number


#: the measurements table of a version-1 store, as that release wrote it (before the part columns)
_VERSION_1 = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE measurements (
    id INTEGER PRIMARY KEY, uuid TEXT NOT NULL UNIQUE, seq INTEGER NOT NULL UNIQUE,
    status TEXT NOT NULL CHECK (status IN ('ok', 'failed', 'aborted')), trigger TEXT NOT NULL,
    device_id TEXT NOT NULL, software_version TEXT NOT NULL, started_at REAL NOT NULL, finished_at REAL NOT NULL,
    stored_at REAL NOT NULL, published_at REAL, J REAL, J_std REAL, omega_n REAL, damping_ratio REAL,
    residual_rms REAL, flags TEXT NOT NULL DEFAULT '[]', error TEXT, payload TEXT, rig TEXT, config TEXT,
    trace_t BLOB, trace_angle BLOB, trace_meta TEXT);
CREATE TABLE outbox (id INTEGER PRIMARY KEY, measurement_id INTEGER NOT NULL REFERENCES measurements (id),
    uuid TEXT NOT NULL, kind TEXT NOT NULL, payload TEXT NOT NULL, created_at REAL NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0, last_attempt REAL);
INSERT INTO meta VALUES ('schema', '1');
INSERT INTO measurements (uuid, seq, status, trigger, device_id, software_version, started_at, finished_at,
    stored_at, J, flags, error) VALUES ('0f0e0d0c-0000-4000-8000-000000000001', 7, 'failed', 'plc', 'old', '0.1',
    100.0, 101.0, 102.0, NULL, '["encoder_gaps"]', 'encoder fault');
"""


def test_a_version_1_store_gains_the_part_columns_and_keeps_its_rows(tmp_path, result):
    from service.persistence.tables import COLUMNS

    db = sqlite3.connect(tmp_path / "results.db")
    db.executescript(_VERSION_1)
    db.close()
    with Store(tmp_path) as store:
        [old] = store.list()
        assert (old.seq, old.status, old.error, old.flags, old.part_id) == (7, "failed", "encoder fault",
                                                                            ("encoder_gaps",), None)
        assert old.operator == "plc"  # schema 4: read from the trigger it was stored with
        m = store.record(status="ok", trigger="button", device_id="new", software_version="9.9", started_at=1.0,
                         finished_at=2.0, result=result[0].to_dict(),
                         part={"part_id": "SN-1", "recipe": "rotor", "release_index": 1, "releases": 1,
                               "verdict": "OK", "part_verdict": "OK", "part_value": 0.0125, "part_U": 1e-5})
        assert m.seq == 8 and (m.part_id, m.recipe, m.part_verdict, m.part_U) == ("SN-1", "rotor", "OK", 1e-5)
        assert m.J == result[0].J and m.flags == tuple(result[0].flags)
        assert store.verdict_counts() == {"OK": 1, "NOK": 0, "INVALID": 0}
    db = sqlite3.connect(tmp_path / "results.db")
    assert [r[1] for r in db.execute("PRAGMA table_info(measurements)")] == [c.name for c in COLUMNS]
    assert db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone() == (str(SCHEMA_VERSION),)
    db.close()


def test_each_consumer_acknowledges_its_own_rows_and_published_at_waits_for_the_last(tmp_path, result):
    """Two store-and-forward publishers: each sees and acknowledges only its rows; the measurement counts as
    published once every consumer has it."""
    with Store(tmp_path) as store:
        m = store_one(store, result, enqueue={"mqtt": ("result",), "sparkplug": ("result",)})
        [a] = store.outbox_pending("mqtt")
        [b] = store.outbox_pending("sparkplug")
        assert a.id != b.id and a.uuid == b.uuid == m.uuid and a.payload == b.payload
        assert (store.outbox_count(), store.outbox_count("mqtt"), store.outbox_count("sparkplug")) == (2, 1, 1)
        assert store.outbox_ack(a.id)
        assert store.outbox_pending("mqtt") == [] and [i.id for i in store.outbox_pending("sparkplug")] == [b.id]
        assert store.get(m.uuid).published_at is None  # Sparkplug does not have it yet
        assert store.outbox_ack(b.id)
        assert store.get(m.uuid).published_at is not None and store.outbox_count() == 0


def test_a_version_2_store_keeps_its_pending_rows_pending_for_mqtt(tmp_path, result):
    """A state directory of the release before rows named their consumer: its unsent results stay MQTT's,
    and a new consumer sees none of them."""
    with Store(tmp_path) as store:
        a = store_one(store, result)
        b = store_one(store, result)
    db = sqlite3.connect(tmp_path / "results.db")  # as version 2 left it: no consumer column
    db.executescript("""
        CREATE TABLE outbox_v2 (id INTEGER PRIMARY KEY, measurement_id INTEGER NOT NULL REFERENCES measurements (id),
            uuid TEXT NOT NULL, kind TEXT NOT NULL, payload TEXT NOT NULL, created_at REAL NOT NULL,
            attempts INTEGER NOT NULL DEFAULT 0, last_attempt REAL);
        INSERT INTO outbox_v2 SELECT id, measurement_id, uuid, kind, payload, created_at, attempts, last_attempt FROM outbox;
        DROP INDEX outbox_consumer; DROP TABLE outbox; ALTER TABLE outbox_v2 RENAME TO outbox;
        UPDATE meta SET value = '2' WHERE key = 'schema';""")
    db.close()
    with Store(tmp_path) as store:
        assert [i.uuid for i in store.outbox_pending("mqtt")] == [a.uuid, b.uuid]
        assert store.outbox_pending("sparkplug") == [] and store.outbox_count("sparkplug") == 0
        [first, _] = store.outbox_pending("mqtt")
        assert store.outbox_ack(first.id) and store.get(a.uuid).published_at is not None
    db = sqlite3.connect(tmp_path / "results.db")
    assert db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone() == (str(SCHEMA_VERSION),)
    assert db.execute("SELECT consumer FROM outbox").fetchall() == [("mqtt",)]
    db.close()


def test_a_version_3_store_gains_the_operator_of_each_run_from_its_trigger(tmp_path):
    """A store of the release before the operator column: every run keeps its row and reads its operator from
    the trigger it was stored with (the named web user, else the door); a new run records its own."""
    with Store(tmp_path) as store:
        for trigger in ("web:alice", "button", "web", "modbus", "web:bob"):
            store.record(status="failed", trigger=trigger, device_id="dev", software_version="9.9", started_at=1.0,
                         finished_at=2.0, error="encoder fault")
    db = sqlite3.connect(tmp_path / "results.db")  # as version 3 left it: no operator column
    db.executescript("""
        ALTER TABLE measurements DROP COLUMN operator;
        UPDATE meta SET value = '3' WHERE key = 'schema';""")
    assert "operator" not in [r[1] for r in db.execute("PRAGMA table_info(measurements)")]
    db.close()
    with Store(tmp_path) as store:
        old = sorted(store.list(limit=None), key=lambda m: m.seq)
        assert [(m.trigger, m.operator) for m in old] == [("web:alice", "alice"), ("button", "button"), ("web", "web"),
                                                           ("modbus", "modbus"), ("web:bob", "bob")]
        new = store.record(status="failed", trigger="web:carol", device_id="dev", software_version="9.9",
                           started_at=3.0, finished_at=4.0, error="encoder fault")
        named = store.record(status="failed", trigger="mqtt", operator="dave", device_id="dev",
                             software_version="9.9", started_at=3.0, finished_at=4.0, error="encoder fault")
        assert (new.operator, named.operator) == ("carol", "dave")
        assert "operator" not in new.summary()  # internal: the exports and `moi results --json` keep their keys
    db = sqlite3.connect(tmp_path / "results.db")
    assert db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone() == (str(SCHEMA_VERSION),) == ("4",)
    # kept only where the trigger does not say it: the row's tail stays empty, after the trace's blobs
    assert db.execute("SELECT trigger, operator FROM measurements WHERE operator IS NOT NULL").fetchall() == [
        ("mqtt", "dave")]
    db.close()


def test_a_new_store_has_the_columns_of_the_table_in_its_order(tmp_path, result):
    from service.persistence.tables import COLUMNS

    with Store(tmp_path) as store:
        m = store_one(store, result)
        full = store.get(m.uuid, trace=True)
    db = sqlite3.connect(tmp_path / "results.db")
    info = [(r[1], r[2], r[3], r[4]) for r in db.execute("PRAGMA table_info(measurements)")]
    db.close()
    assert [name for name, *_ in info] == [c.name for c in COLUMNS]
    assert [kind for _, kind, *_ in info] == [c.sql.split()[0] for c in COLUMNS]
    assert ("flags", "TEXT", 1, "'[]'") in info and ("status", "TEXT", 1, None) in info
    assert full is not None and np.array_equal(full.trace_t, result[1].t) and full.rig == result[2].to_dict()
    assert full.trace_meta == {"encoder": {"samples": len(result[1])}}
