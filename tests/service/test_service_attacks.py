"""Attacks on the running appliance (simulated rig, everything on loopback): hostile MQTT payloads,
illegal Modbus writes, connection floods. Each attack is bounded in count and time."""

from __future__ import annotations

import json
import socket
import struct

import pytest

from service import registers as R
from service.mqtt import MqttService, MqttSettings
from service.store import Store

from .conftest import appliance_doc, free_port, wait_until

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


# --- Modbus: illegal coil values, echo replies -----------------------------------------------------------------

def _mbap(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def _tcp_exchange(sock: socket.socket, tid: int, unit: int, pdu: bytes) -> bytes:
    """Send one Modbus TCP request, return the reply's PDU."""
    sock.sendall(_mbap(tid, unit, pdu))
    head = _recv_exact(sock, 7)
    rtid, _, length, runit = struct.unpack(">HHHB", head)
    assert (rtid, runit) == (tid, unit)
    return _recv_exact(sock, length - 1)


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        assert chunk, "connection closed"
        data += chunk
    return data


ILLEGAL_COIL_VALUES = (0x1234, 0xFF01, 0x00FF, 0xFFFF, 0x0001)


def test_illegal_coil_values_are_exception_03_and_fire_nothing_and_legal_writes_are_echoed(tmp_path, appliance_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state"))
    fired: list[str] = []
    forward = app.app.modbus._on_command
    app.app.modbus._on_command = lambda name, source: (fired.append(name), forward(name, source))
    with socket.create_connection(("127.0.0.1", app.app.modbus.bound_port), timeout=5) as s:
        for tid, value in enumerate(ILLEGAL_COIL_VALUES, 1):
            reply = _tcp_exchange(s, tid, 1, struct.pack(">BHH", 5, R.COILS["trigger"], value))
            assert reply == bytes([0x85, 0x03]), (hex(value), reply)
        # nothing started: the sequencer saw no request (the live counter is read by a PLC too)
        assert fired == []
        for tid, (coil, value) in enumerate([(R.COILS["abort"], 0x0000), (R.COILS["trigger"], 0xFF00)], 100):
            request = struct.pack(">BHH", 5, coil, value)
            assert _tcp_exchange(s, tid, 1, request) == request  # the normal response is an echo
    app.wait_done(1)
    assert fired == ["trigger"] and app.states().count("ARMED") == 1


def _crc(frame: bytes) -> bytes:
    crc = 0xFFFF
    for b in frame:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)


def test_rtu_single_coil_writes_are_echoed_and_illegal_values_refused():
    from service.modbus_server import ModbusServer, ModbusSettings

    port = free_port()
    commands: list[str] = []
    srv = ModbusServer(ModbusSettings(mode="rtu", serial_port=f"socket://127.0.0.1:{port}", unit_id=5),
                       on_command=lambda name, source: commands.append(name))
    srv.start()
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
            for value in ILLEGAL_COIL_VALUES:
                frame = struct.pack(">BBHH", 5, 5, R.COILS["trigger"], value)
                s.sendall(frame + _crc(frame))
                reply = _recv_exact(s, 5)
                assert reply[:3] == bytes([5, 0x85, 0x03]) and reply[3:] == _crc(reply[:3]), (hex(value), reply)
            frame = struct.pack(">BBHH", 5, 5, R.COILS["trigger"], 0xFF00)
            s.sendall(frame + _crc(frame))
            assert _recv_exact(s, 8) == frame + _crc(frame)
    finally:
        srv.stop()
    assert commands == ["trigger"]
