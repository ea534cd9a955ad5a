"""The appliance end to end on the simulated rig, with a real Mosquitto and a real pymodbus client."""

from __future__ import annotations

import json
import math
import threading

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

from measurement import flags as F
from service.persistence.store import Store
from service.publish.modbus import registers as R
from tests.service.conftest import appliance_doc, wait_until

pytestmark = pytest.mark.broker


def modbus_client(app) -> ModbusTcpClient:
    c = ModbusTcpClient("127.0.0.1", port=app.app.modbus.bound_port, timeout=3, retries=0)
    assert c.connect()
    return c


def read_all(c: ModbusTcpClient) -> dict:
    rr = c.read_input_registers(0, count=R.IMAGE_SIZE, device_id=1)
    assert not rr.isError(), rr
    return R.decode_image(rr.registers)


def f32(x):
    return float(np.float32(x)) if x is not None else math.nan


def same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


def test_button_measurement_arrives_on_mqtt_and_in_modbus_with_the_same_values(tmp_path, broker, appliance_factory,
                                                                                consumer_factory):
    c = consumer_factory(broker.port, ["moi/test-rig/#"])
    c.wait_subscribed()
    # the whole simulated appliance: mock pins, SimRig, a Modbus RTU encoder server read by the real client
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port, time_scale=2.0,
                                          simulation={"sensor": "encoder"}))
    c.wait(lambda c: c.on("/status")[-1:] == [b"online"], 10, "online status")
    app.press()
    c.wait(lambda c: len(c.results()) >= 1, 30, "a result on MQTT")
    [msg] = c.results()
    # the fields a consumer relies on
    for key in ("uuid", "seq", "device_id", "software_version", "trigger", "started_at", "finished_at", "timestamp",
                "J", "J_std", "omega_n", "damping_ratio", "damping", "effects", "added_effects", "flags",
                "residual_rms_before", "residual_rms_after", "noise_floor", "baseline"):
        assert key in msg, key
    assert msg["trigger"] == "button" and msg["device_id"] == "test-rig" and msg["status"] == "ok"
    assert abs(msg["J"] / app.app.devices.sim.inertia - 1) < 2e-3  # the simulated truth
    assert msg["acquisition"]["encoder"]["samples"] > 100
    assert "viscous" in msg["damping"] and msg["residual_rms_after"] == msg["residual_rms"]
    assert msg["started_at"] < msg["finished_at"]
    # the store holds exactly what was published
    stored = app.app.store.get(msg["uuid"])
    assert stored.payload == msg and stored.trigger == "button"
    # the PLC reads the same values, exact to float32
    mb = modbus_client(app)
    try:
        values = read_all(mb)
    finally:
        mb.close()
    assert values["uuid"] == msg["uuid"] and values["seq"] == values["seq_end"] == R.modbus_seq(msg["seq"])
    for reg, key in (("J", "J"), ("J_std", "J_std"), ("omega_n", "omega_n"), ("omega_n_std", "omega_n_std"),
                     ("damping_ratio", "damping_ratio"), ("residual_rms", "residual_rms_after"),
                     ("residual_rms_before", "residual_rms_before"), ("noise_floor", "noise_floor"),
                     ("J_object", "J_object")):
        assert same(values[reg], f32(msg[key])), reg
    assert values["flags"] | values["flags_high"] << 16 == msg["flag_bits"] == F.flag_bits(msg["flags"])
    assert values["timestamp"] == int(msg["timestamp"])
    assert values["measurements_started"] == 1
    # the sequencer's transitions were published on the state topic, in order
    c.wait(lambda c: json.loads(c.on("/state")[-1])["state"] == "IDLE", 10, "IDLE after the result")
    states = [json.loads(p)["state"] for p in c.on("/state")]
    assert states[-6:] == ["ARMED", "RELEASING", "CAPTURING", "IDENTIFYING", "PUBLISHING", "IDLE"]
    assert app.stop() == 0
    c.wait(lambda c: c.on("/status")[-1:] == [b"offline"], 10, "offline status after stop")


def test_broker_down_during_three_measurements_then_up_all_arrive_once_each(tmp_path, persistent_broker,
                                                                         appliance_factory, consumer_factory):
    c = consumer_factory(persistent_broker.port, ["moi/test-rig/result"], client_id="plant-db", persistent=True)
    c.wait_subscribed()
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=persistent_broker.port))
    assert app.app.mqtt.connected_event.wait(10)
    persistent_broker.stop()
    wait_until(lambda: not app.app.mqtt.is_connected, 10, what="the daemon to notice the broker is gone")

    # a PLC reads the snapshot in a tight loop all along: every read must be one stored measurement
    mb = modbus_client(app)
    stop = threading.Event()
    seen: list[dict] = []
    reader_error: list[BaseException] = []

    def plc():
        try:
            while not stop.is_set():
                rr = mb.read_input_registers(R.SNAPSHOT_START, count=R.SNAPSHOT_END - R.SNAPSHOT_START, device_id=1)
                seen.append(R.decode_image(rr.registers, start=R.SNAPSHOT_START))
        except BaseException as exc:  # handed to the test thread
            reader_error.append(exc)

    reader = threading.Thread(target=plc, daemon=True)
    reader.start()
    try:
        for i in range(1, 4):
            app.press()
            app.wait_done(i)
    finally:
        stop.set()
        reader.join(10)
        mb.close()
    assert not reader_error, reader_error
    uuids = list(app.app.stored)
    assert app.app.store.outbox_count() == 3  # all three wait in the outbox
    assert c.results() == []

    persistent_broker.start()
    c.wait(lambda c: len(c.unique_results()) == 3, 30, "three results after the broker came back")
    assert list(c.unique_results()) == uuids
    assert app.app.mqtt.sender.wait_empty(10)
    assert app.app.store.outbox_count() == 0

    # no torn snapshot: each read equals the stored payload of its uuid, register for register
    payloads = {u: app.app.store.get(u).payload for u in uuids}
    by_uuid = {u: R.decode_image(R.encode_snapshot(p), start=R.SNAPSHOT_START) for u, p in payloads.items()}
    assert len({s["uuid"] for s in seen}) >= 2, "the PLC did not see the results change"
    for s in seen:
        if s["seq"] == 0:
            assert s["uuid"] is None
            continue
        expected = by_uuid[s["uuid"]]
        assert all(same(v, expected[k]) if isinstance(v, float) else v == expected[k] for k, v in s.items()), s
    assert app.stop() == 0


def test_coil_and_mqtt_triggers_start_exactly_one_measurement_each(tmp_path, broker, appliance_factory,
                                                                     consumer_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.connected_event.wait(10)
    mb = modbus_client(app)
    c = consumer_factory(broker.port, ["moi/test-rig/status"])
    c.wait_subscribed()
    try:
        assert not mb.write_coil(R.COILS["trigger"], True, device_id=1).isError()
        app.wait_done(1)
        c.publish("moi/test-rig/cmd/measure", json.dumps({"id": "line-7-part-42"}))
        app.wait_done(2)
        values = read_all(mb)
    finally:
        mb.close()
    assert values["measurements_started"] == 2
    rows = app.app.store.list()
    assert [m.trigger for m in reversed(rows)] == ["modbus", "mqtt"]
    assert [m.status for m in rows] == ["ok", "ok"]
    assert app.app.sequencer.counts["measurements"] == 2


def test_a_trigger_while_measuring_is_ignored(tmp_path, appliance_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", time_scale=5.0))
    app.press()
    app.wait_event(lambda e: e.state.value == "CAPTURING", 20)
    app.app.command("trigger", "modbus")  # during the swing
    app.press()
    app.wait_done(1)
    assert app.states().count("ARMED") == 1
    assert app.app.sequencer.counts["ignored_requests"] == 2


def test_a_sensor_fault_is_published_and_the_abort_coil_acknowledges_it(tmp_path, broker, appliance_factory,
                                                                          consumer_factory):
    c = consumer_factory(broker.port, ["moi/test-rig/state"])
    c.wait_subscribed()
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port, time_scale=5.0))
    app.press()
    app.wait_event(lambda e: e.state.value == "CAPTURING", 20)
    app.app.devices.sensor.inject_fault("encoder: 8 time-outs in a row")
    c.wait(lambda c: any(json.loads(p)["state"] == "FAULT" for p in c.on("/state")), 20, "FAULT on MQTT")
    fault = [json.loads(p) for p in c.on("/state") if json.loads(p)["state"] == "FAULT"][0]
    assert "8 time-outs" in fault["reason"]
    assert not app.app.devices.solenoid.is_active
    mb = modbus_client(app)
    try:
        wait_until(lambda: read_all(mb)["state"] == R.STATE_CODES["FAULT"], 10, what="FAULT in the registers")
        assert read_all(mb)["status"] & (1 << R.STATUS_BITS["fault"])
        mb.write_coil(R.COILS["abort"], True, device_id=1)
        wait_until(lambda: read_all(mb)["state"] == R.STATE_CODES["IDLE"], 10, what="IDLE after the abort coil")
    finally:
        mb.close()
    assert app.app.wait_stored(1, 10)
    [row] = app.app.store.list()
    assert row.status == "failed" and "8 time-outs" in row.error


def test_stop_during_a_capture_aborts_solenoid_off_and_records_the_abort(tmp_path, appliance_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", time_scale=2.0))
    pin = app.app.devices.solenoid.pin
    app.press()
    app.wait_event(lambda e: e.state.value == "CAPTURING", 20)
    assert app.stop() == 0
    assert pin.state in (0, False)  # the mock pin was left de-energised
    with Store(tmp_path / "state") as store:
        [row] = store.list()
        assert row.status == "aborted" and "stopping" in row.error
