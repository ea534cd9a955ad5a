"""Attacks on the running appliance (simulated rig, everything on loopback): hostile MQTT payloads,
illegal Modbus writes, connection floods. Each attack is bounded in count and time."""

from __future__ import annotations

import json
import socket
import struct
from pathlib import Path

import numpy as np
import pytest

from service.persistence.store import Store
from service.publish.modbus import registers as R
from service.publish.mqtt.client import MqttService, MqttSettings
from tests.service.conftest import appliance_doc, free_port, wait_until

pytestmark = pytest.mark.broker


def test_a_deeply_nested_json_command_neither_stops_mqtt_nor_its_acknowledgements(tmp_path, broker, appliance_factory,
                                                                                  consumer_factory):
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.subscribed_event.wait(10)
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

    def on_command(name: str, source: str, data=None, reply=None) -> None:
        got.append(name)
        if len(got) == 1:
            raise RuntimeError("handler bug")

    store = Store(tmp_path / "state")
    svc = MqttService(MqttSettings(host="127.0.0.1", port=broker.port, reconnect_min=0.1, reconnect_max=0.5),
                      "rig", store, on_command=on_command)
    svc.start()
    try:
        assert svc.subscribed_event.wait(10)
        c = consumer_factory(broker.port, ["moi/rig/status"])
        c.wait_subscribed()
        c.publish("moi/rig/cmd/measure", "1")
        c.publish("moi/rig/cmd/abort", "1")
        wait_until(lambda: len(got) == 2, 10, what="the second command")
        assert got == ["trigger", "abort"]
        assert svc.callback_errors == 1 and "handler bug" in (svc.last_error or "")
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

    def spy(name, source, *more):
        fired.append(name)
        return forward(name, source, *more)
    app.app.modbus._on_command = spy
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
    """The RTU CRC as it goes on the wire (low byte first), from the encoder driver's one CRC."""
    from drivers.encoder import _crc16

    return struct.pack("<H", _crc16(frame))


def test_rtu_single_coil_writes_are_echoed_and_illegal_values_refused():
    from service.publish.modbus.server import ModbusServer, ModbusSettings

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


# --- Modbus: connection floods ------------------------------------------------------------------------------

def _closed_by_peer(sock: socket.socket, timeout: float) -> bool:
    """True if the server closes ``sock`` within ``timeout`` s (a read returns end of file or a reset)."""
    sock.settimeout(timeout)
    try:
        return sock.recv(1) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def _read_request(tid: int) -> bytes:
    return _mbap(tid, 1, struct.pack(">BHH", 4, 0, 2))


def test_the_connection_cap_closes_the_longest_idle_connection_first():
    from service.publish.modbus.server import ModbusServer, ModbusSettings

    srv = ModbusServer(ModbusSettings(host="127.0.0.1", port=0, max_connections=3, idle_timeout=0))
    srv.start()
    socks = []
    try:
        for _ in range(3):
            socks.append(socket.create_connection(("127.0.0.1", srv.bound_port), timeout=5))
        wait_until(lambda: srv.client_count() == 3, 5, what="three connections")
        _tcp_exchange(socks[0], 1, 1, struct.pack(">BHH", 4, 0, 2))  # the first one is active: not the oldest idle
        socks.append(socket.create_connection(("127.0.0.1", srv.bound_port), timeout=5))
        assert _closed_by_peer(socks[1], 5), "the longest idle connection was not closed"
        assert not _closed_by_peer(socks[2], 0.2) and not _closed_by_peer(socks[0], 0.05)
        assert len(_tcp_exchange(socks[3], 2, 1, struct.pack(">BHH", 4, 0, 2))) == 6  # the newcomer is served
        assert srv.client_count() == 3 and srv.connections_dropped == 1
    finally:
        for s in socks:
            s.close()
        srv.stop()


def test_an_idle_connection_is_closed_and_an_active_one_is_not():
    from service.publish.modbus.server import ModbusServer, ModbusSettings

    srv = ModbusServer(ModbusSettings(host="127.0.0.1", port=0, idle_timeout=0.5))
    srv.start()
    try:
        with socket.create_connection(("127.0.0.1", srv.bound_port), timeout=5) as idle, \
                socket.create_connection(("127.0.0.1", srv.bound_port), timeout=5) as busy:
            for tid in range(12):  # 1.2 s of polling every 0.1 s: longer than the time-out
                assert len(_tcp_exchange(busy, tid, 1, struct.pack(">BHH", 4, 0, 2))) == 6
                if _closed_by_peer(idle, 0.1):
                    break
            else:
                raise AssertionError("the idle connection was not closed")
            assert len(_tcp_exchange(busy, 99, 1, struct.pack(">BHH", 4, 0, 2))) == 6
    finally:
        srv.stop()


def test_a_flood_of_idle_connections_does_not_lock_the_plc_or_mqtt_out(tmp_path, broker, consumer_factory):
    """1,100 idle connections against the daemon process (its descriptor limit 1024, LimitNOFILE of the
    unit): a PLC still connects and reads, a measurement still goes out on MQTT."""
    import resource
    import time

    from tests.service.conftest import moi_subprocess, port_open, write_toml

    mb_port = free_port()
    cfg = write_toml(tmp_path / "appliance.toml", appliance_doc(tmp_path / "state", mqtt_port=broker.port,
                                                                modbus_port=mb_port))
    c = consumer_factory(broker.port, ["moi/test-rig/result", "moi/test-rig/status"])
    c.wait_subscribed()
    daemon = moi_subprocess(["run", "--config", str(cfg)],
                            preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (1024, 1024)))
    flood: list[socket.socket] = []
    try:
        wait_until(lambda: port_open(mb_port) or daemon.poll() is not None, 30, what="the daemon's Modbus port")
        assert daemon.poll() is None
        c.wait(lambda c: c.on("/status")[-1:] == [b"online"], 20, "online")
        for _ in range(1100):
            try:
                flood.append(socket.create_connection(("127.0.0.1", mb_port), timeout=5))
            except OSError:
                break  # the listen backlog is full: the attacker could not even queue more
        assert len(flood) > 1024, f"only {len(flood)} attack connections: the attack proved nothing"
        t0 = time.monotonic()
        with socket.create_connection(("127.0.0.1", mb_port), timeout=5) as plc:
            reply = _tcp_exchange(plc, 1, 1, struct.pack(">BHH", 4, 0, R.IMAGE_SIZE))
            plc_ms = (time.monotonic() - t0) * 1e3
            assert len(reply) == 2 + 2 * R.IMAGE_SIZE
            status = R.decode_image(list(struct.unpack(f">{R.IMAGE_SIZE}H", reply[2:])))["status"]
            assert status & (1 << R.STATUS_BITS["mqtt_connected"])
            trigger = struct.pack(">BHH", 5, R.COILS["trigger"], 0xFF00)
            assert _tcp_exchange(plc, 2, 1, trigger) == trigger
        c.wait(lambda c: len(c.unique_results()) == 1, 60, "the result on MQTT")
        print(f"{len(flood)} idle connections: a PLC connected and read the map in {plc_ms:.0f} ms")
    finally:
        for s in flood:
            s.close()
        daemon.terminate()
        daemon.communicate(timeout=30)


def _connect_from(source: str, port: int) -> socket.socket:
    s = socket.socket()
    s.settimeout(5)
    s.bind((source, 0))
    s.connect(("127.0.0.1", port))
    return s


def test_only_this_machine_and_the_allow_list_get_in():
    """Clients bound to other loopback addresses stand for other hosts: 127.0.0.3 is allowed, 127.0.0.2 is not."""
    from service.publish.modbus.server import ModbusServer, ModbusSettings

    srv = ModbusServer(ModbusSettings(host="127.0.0.1", port=0, allow_from=("127.0.0.3",)))
    srv.start()
    assert srv.bound_port is not None
    try:
        with _connect_from("127.0.0.2", srv.bound_port) as stranger:
            assert _closed_by_peer(stranger, 5), "a client outside allow_from was served"
        for source in ("127.0.0.3", "127.0.0.1"):
            with _connect_from(source, srv.bound_port) as friend:
                assert len(_tcp_exchange(friend, 1, 1, struct.pack(">BHH", 4, 0, 2))) == 6
        assert srv.connections_refused == 1
    finally:
        srv.stop()


def test_listening_beyond_this_machine_is_a_stated_choice():
    from service.config.appliance import parse_config
    from service.errors import ConfigError
    from service.publish.modbus.server import ModbusSettings, network_exposure

    assert parse_config({}, source="empty.toml").modbus.host == "127.0.0.1"
    assert network_exposure(ModbusSettings()) is None
    assert "every client" in (network_exposure(ModbusSettings(host="0.0.0.0")) or "")
    assert "192.168.10.20" in (network_exposure(ModbusSettings(host="0.0.0.0", allow_from=("192.168.10.20",))) or "")
    with pytest.raises(ConfigError, match="allow_from: 'plc-1' is not an IP address"):
        parse_config({"modbus": {"allow_from": ["plc-1"]}}, source="bad.toml")


# --- nothing leaves the device before it is durable -----------------------------------------------------------

def test_a_result_that_cannot_be_stored_never_leaves_the_device(tmp_path, broker, appliance_factory, consumer_factory):
    """A full disk, made by SQLite's own page limit: the store write fails, the measurement ends in FAULT,
    and neither the MQTT state nor the result topic ever carried its J."""
    c = consumer_factory(broker.port, ["moi/test-rig/#"])
    c.wait_subscribed()
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.subscribed_event.wait(10)
    db = app.app.store._db
    db.execute(f"PRAGMA max_page_count = {db.execute('PRAGMA page_count').fetchone()[0]}")  # the disk is full
    app.press()
    app.wait_event(lambda e: e.state.value == "FAULT", 30, what="FAULT after the failed store write")
    c.wait(lambda c: any(json.loads(p).get("state") == "FAULT" for p in c.on("/state")), 10, "FAULT on MQTT")
    measured = app.app.sequencer.last_measurement
    published = [json.loads(p) for p in c.on("/state")]
    assert [m["state"] for m in published][-3:] == ["IDENTIFYING", "PUBLISHING", "FAULT"]
    assert all("J" not in m and "J =" not in (m.get("reason") or "") for m in published), published
    assert c.results() == [] and measured is None


# --- runaway captures -----------------------------------------------------------------------------------------

def test_the_capture_is_bounded_by_sample_time_at_the_largest_time_scale(tmp_path, appliance_factory):
    """At 1000× a 20 ms poll is 20 simulated seconds: the record must still end 20 s after the release
    (it ran to 2,300 s and 230,000 rows when the capture was bounded by poll time only) and start at most
    the pre-trigger before it (a release that came seconds late stretched the record to 25 s). The main
    loop polls every 50 ms here, as a busy machine may run it: nothing asserted depends on when it runs."""
    pre, duration, rate = 0.2, 20.0, 100.0
    app = appliance_factory(appliance_doc(tmp_path / "state", time_scale=1000.0,
                                          sequencer={"pre_trigger": pre, "capture_duration": duration},
                                          simulation={"rate": rate}), poll_interval=0.05)
    app.press()
    app.wait_done(1, timeout=60)
    m = app.app.store.latest("ok")
    stored = app.app.store.get(m.uuid, trace=True)
    release = stored.trace_meta["sequencer"]["release_t"]
    # after the release: exactly the window, however late the poll came
    assert stored.trace_t[-1] - release == pytest.approx(duration, abs=2 / rate)
    # before it: the pre-trigger, however late the release came (one sample of slack either side)
    assert pre - 2 / rate <= release <= pre + 2 / rate
    t = np.asarray(stored.trace_t)
    assert len(t) <= (t[-1] - t[0]) * rate + 2  # one row per sample, nothing piled up
    enc = stored.trace_meta.get("direct") or next(v for k, v in stored.trace_meta.items() if k != "sequencer")
    assert enc["samples"] - enc.get("outside_window", 0) == len(t)  # what was left out is counted


# --- two daemons on one state directory -------------------------------------------------------------------------

def test_a_second_daemon_on_the_same_state_directory_stops_with_one_line(tmp_path):
    from tests.service.conftest import moi_subprocess, port_open, write_toml

    first_port, second_port = free_port(), free_port()
    state = tmp_path / "state"
    first_cfg = write_toml(tmp_path / "first.toml", appliance_doc(state, modbus_port=first_port))
    second_cfg = write_toml(tmp_path / "second.toml", appliance_doc(state, modbus_port=second_port))
    first = moi_subprocess(["run", "--config", str(first_cfg)])
    try:
        wait_until(lambda: port_open(first_port) or first.poll() is not None, 30, what="the first daemon")
        assert first.poll() is None
        second = moi_subprocess(["run", "--config", str(second_cfg)])
        _, err = second.communicate(timeout=60)
        lines = [line for line in err.decode().splitlines() if line.startswith("moi run:")]
        assert second.returncode == 3 and len(lines) == 1 and "another moi daemon (pid" in lines[0], err.decode()
        assert "Traceback" not in err.decode() and not port_open(second_port)
    finally:
        first.terminate()
        first.communicate(timeout=30)
    assert first.returncode == 0


# --- MQTT connection failures are said --------------------------------------------------------------------------

@pytest.mark.parametrize("case", ["port refused", "TLS against a plain broker"])
def test_mqtt_connection_failures_are_logged_once_and_shown_in_the_status(tmp_path, broker, caplog, case):
    import logging

    caplog.set_level(logging.WARNING, logger="moi.mqtt")
    port = free_port() if case == "port refused" else broker.port
    settings = MqttSettings(host="127.0.0.1", port=port, reconnect_min=0.05, reconnect_max=0.1,
                            tls=case != "port refused")
    store = Store(tmp_path / "state")
    attempts: list[str] = []
    svc = MqttService(settings, "rig", store)
    forward = svc.client.on_connect_error
    assert forward is not None

    def count(exc):
        attempts.append(type(exc).__name__)
        forward(exc)
    svc.client.on_connect_error = count
    svc.start()
    try:
        wait_until(lambda: len(attempts) >= 3, 20, what="three connection attempts")
        expected = "ConnectionRefusedError" if case == "port refused" else "ConnectionResetError"  # the TLS hello rejected
        assert expected in (svc.last_error or ""), svc.last_error
        said = [r.getMessage() for r in caplog.records if "cannot connect" in r.getMessage()]
        assert len(said) == 1 and expected in said[0] and f"127.0.0.1:{port}" in said[0], said
        assert not svc.is_connected
    finally:
        svc.stop()
        store.close()


# --- minor items ----------------------------------------------------------------------------------------------

def test_a_measurement_key_is_a_literal_prefix_not_a_pattern(tmp_path, capsys):
    from service.cli import main

    with Store(tmp_path / "s") as s:
        s.record(status="failed", trigger="button", device_id="rig", software_version="t", started_at=1.0,
                 finished_at=2.0, error="test")
    for key in ("%", "_", "%%%"):
        assert main(["results", key, "--state-dir", str(tmp_path / "s")]) == 2
        assert "no single measurement matches" in capsys.readouterr().err


def test_a_world_readable_password_file_is_warned_about(tmp_path, caplog):
    import logging

    secret = tmp_path / "mqtt-password"
    secret.write_text("hunter2\n")
    secret.chmod(0o644)
    store = Store(tmp_path / "state")
    try:
        with caplog.at_level(logging.WARNING, logger="moi.mqtt"):
            MqttService(MqttSettings(username="moi", password_file=str(secret)), "rig", store)
        assert any("readable by every user" in r.getMessage() for r in caplog.records)
        assert all("hunter2" not in r.getMessage() for r in caplog.records)
    finally:
        store.close()


def test_ignored_triggers_are_logged_at_most_once_per_interval(tmp_path, appliance_factory, caplog):
    import logging

    caplog.set_level(logging.INFO, logger="moi.daemon")
    app = appliance_factory(appliance_doc(tmp_path / "state", time_scale=5.0))
    app.press()
    app.wait_event(lambda e: e.state.value == "CAPTURING", 20)
    for _ in range(50):
        app.app.command("trigger", "modbus")  # a PLC holding the trigger
    wait_until(lambda: app.app.sequencer.counts["ignored_requests"] >= 50, 20, what="50 ignored triggers")
    lines = [r for r in caplog.records if r.getMessage().startswith("trigger from")]
    assert len(lines) == 1, [r.getMessage() for r in lines]
    app.wait_done(1)


# --- moi run --check ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("hardware", "mqtt", "expected"), [
    ('solenoid = { pin = 17 }\nbutton = { pin = "GPIO17" }', "", "already the solenoid's pin"),
    ("solenoid = { pin = 99999 }", "", "99999 is not a GPIO pin"),
    ('solenoid = { pin = "BANANA" }', "", "'BANANA' is not a GPIO pin"),
    ("solenoid = { pin = 17 }", 'username = "moi"\npassword_file = "/nonexistent/secret"',
     "password_file: /nonexistent/secret does not exist"),
    ("solenoid = { pin = 17 }", 'tls = true\nca_file = "/nonexistent/ca.pem"', "ca_file: /nonexistent/ca.pem does not exist"),
])
def test_check_finds_what_would_crash_the_start(tmp_path, capsys, hardware, mqtt, expected):
    from service.cli import main

    rig = tmp_path.parent / "rig.toml"
    cfg = tmp_path / "appliance.toml"
    cfg.write_text(f'[device]\nrig = "{Path(__file__).resolve().parents[2] / "examples" / "torsion_rig.toml"}"\n'
                   f'state_dir = "{tmp_path / "state"}"\n[hardware]\ngpio_backend = "mock"\nsensor = "encoder"\n'
                   f'encoder = {{ port = "socket://127.0.0.1:1" }}\n{hardware}\n'
                   f'[modbus]\nport = 0\n[web]\nenabled = false\n'
                   + (f'[mqtt]\nhost = "127.0.0.1"\n{mqtt}\n' if mqtt else ""))
    assert main(["run", "--check", "--config", str(cfg)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], captured.err
    assert "PROBLEM" in captured.out and "ok " in captured.out  # the human summary
    assert not rig.exists()
    if "pin" in expected:  # starting is the same clear line, not a gpiozero traceback
        assert main(["run", "--config", str(cfg)]) == 2
        assert expected in capsys.readouterr().err


def test_check_passes_a_good_configuration_and_says_so_as_json(tmp_path, capsys):
    from service.cli import main

    cfg = tmp_path / "appliance.toml"
    cfg.write_text(f'[device]\nstate_dir = "{tmp_path / "state"}"\n[modbus]\nport = 0\n[web]\nenabled = false\n')
    assert main(["run", "--check", "--json", "--config", str(cfg)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["checks"] and all(c["ok"] for c in doc["checks"])


def test_the_latest_delivered_result_is_retained_for_home_assistant(tmp_path, broker, consumer_factory):
    store = Store(tmp_path / "state")
    svc = MqttService(MqttSettings(host="127.0.0.1", port=broker.port, reconnect_min=0.1, reconnect_max=0.5),
                      "rig", store)
    svc.start()
    try:
        for i in range(2):
            store.record(status="ok", trigger="button", device_id="rig", software_version="t", started_at=1e9 + i,
                         finished_at=1e9 + i + 1, result={"J": 0.01 + i, "flags": []}, enqueue={"mqtt": ("result",)},
                         build_payload=lambda u, q: {"uuid": u, "seq": q, "J": 0.01 + q, "timestamp": 1e9})
        svc.wake()
        wait_until(lambda: store.outbox_count() == 0, 20, what="both results delivered")
        late = consumer_factory(broker.port, ["moi/rig/result/last"], client_id="home-assistant-restarted")
        late.wait(lambda c: c.on("/result/last"), 10, "the retained last result")
        assert json.loads(late.on("/result/last")[-1])["seq"] == 2 and late.messages[-1][2]  # retained, newest
    finally:
        svc.stop()
        store.close()


def test_state_messages_name_their_counter_apart_from_the_result_seq(tmp_path, broker, appliance_factory,
                                                                     consumer_factory):
    c = consumer_factory(broker.port, ["moi/test-rig/state", "moi/test-rig/result"])
    c.wait_subscribed()
    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.subscribed_event.wait(10)
    app.press()
    app.wait_done(1)
    c.wait(lambda c: c.results(), 20, "the result")
    c.wait(lambda c: any(json.loads(p)["state"] == "IDLE" and json.loads(p).get("measurement_id")
                         for p in c.on("/state")), 10, "IDLE after the measurement")
    states = [json.loads(p) for p in c.on("/state")]
    events = [s for s in states if s.get("measurement_id")]
    assert events and all("seq" not in s and isinstance(s["transition"], int) for s in events), events
    assert c.results()[0]["seq"] == 1
