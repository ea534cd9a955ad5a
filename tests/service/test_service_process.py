"""`moi run` as a separate process, as systemd runs it: sd_notify, SIGTERM, SIGKILL and restart."""

from __future__ import annotations

import signal
import socket
import subprocess
import time

import pytest
from pymodbus.client import ModbusTcpClient

from service.persistence.store import Store
from service.publish.modbus import registers as R
from tests.service.conftest import appliance_doc, free_port, moi_subprocess, port_open, wait_until, write_toml


def start_daemon(config_path, env_extra=None) -> subprocess.Popen:
    return moi_subprocess(["run", "--config", str(config_path)], env_extra=env_extra)


def stop_daemon(proc: subprocess.Popen, sig=signal.SIGTERM, timeout: float = 30) -> tuple[int, str]:
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate(timeout=10)
        raise AssertionError(f"daemon did not stop on {sig!r}: {err.decode(errors='replace')[-3000:]}") from None
    return proc.returncode, err.decode(errors="replace")


def read_snapshot(port: int) -> dict:
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=3, retries=0)
    try:
        if not c.connect():
            return {}
        rr = c.read_input_registers(0, count=R.IMAGE_SIZE, device_id=1)
        return {} if rr.isError() else R.decode_image(rr.registers)
    finally:
        c.close()


def trigger_and_wait(port: int, n_started: int, timeout: float = 60) -> None:
    """Write the trigger coil, then wait (like a PLC) for the measurement to start and to end in IDLE."""
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=3, retries=0)
    assert c.connect()
    try:
        assert not c.write_coil(R.COILS["trigger"], True, device_id=1).isError()
    finally:
        c.close()
    wait_until(lambda: (s := read_snapshot(port)) and s["measurements_started"] == n_started
               and s["state"] == R.STATE_CODES["IDLE"], timeout, 0.05, f"measurement {n_started} to finish")


@pytest.mark.broker
def test_nothing_is_lost_when_the_daemon_is_killed_while_the_broker_is_down(tmp_path, persistent_broker,
                                                                            consumer_factory):
    state = tmp_path / "state"
    mb_port = free_port()
    cfg = write_toml(tmp_path / "appliance.toml", appliance_doc(state, mqtt_port=persistent_broker.port,
                                                                modbus_port=mb_port))
    consumer = consumer_factory(persistent_broker.port, ["moi/test-rig/#"], client_id="historian", persistent=True)
    consumer.wait_subscribed()
    persistent_broker.stop()

    daemon = start_daemon(cfg)
    try:
        wait_until(lambda: port_open(mb_port) or daemon.poll() is not None, 30, what="the daemon's Modbus port")
        assert daemon.stderr is not None
        assert daemon.poll() is None, daemon.stderr.read().decode()
        for i in (1, 2, 3):
            trigger_and_wait(mb_port, i)
    finally:
        daemon.kill()  # SIGKILL: no graceful anything
        daemon.communicate(timeout=10)
    with Store(state) as store:
        stored = [m.uuid for m in reversed(store.list())]
        assert len(stored) == 3 and store.outbox_count() == 3

    persistent_broker.start()
    daemon = start_daemon(cfg)
    try:
        consumer.wait(lambda c: len(c.unique_results()) == 3, 60, "the three results after the restart")
        assert list(consumer.unique_results()) == stored
        # the restarted daemon serves the last stored result to the PLC straight away
        assert read_snapshot(mb_port)["uuid"] == stored[-1]
        wait_until(lambda: (s := read_snapshot(mb_port)) and s["state"] == R.STATE_CODES["IDLE"]
                   and s["outbox_pending"] == 0, 30, 0.05, "the daemon idle with an empty outbox")
        # killed while connected, the broker publishes the last will
        consumer.wait(lambda c: c.on("/status")[-1:] == [b"online"], 10, "online")
    finally:
        daemon.kill()
        daemon.communicate(timeout=10)
    consumer.wait(lambda c: c.on("/status")[-1:] == [b"offline"], 30, "the last will (offline)")
    with Store(state) as store:
        assert store.outbox_count() == 0
        assert all(m.published_at is not None for m in store.list())


def test_the_daemon_notifies_systemd_ready_and_pings_the_watchdog_then_stops_on_sigterm(tmp_path):
    sock_path = str(tmp_path / "notify.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(sock_path)
    sock.settimeout(30)
    cfg = write_toml(tmp_path / "appliance.toml", appliance_doc(tmp_path / "state"))
    daemon = start_daemon(cfg, env_extra={"NOTIFY_SOCKET": sock_path, "WATCHDOG_USEC": "300000"})
    try:
        messages: list[dict[str, str]] = []

        def receive() -> dict[str, str]:
            data = sock.recv(4096).decode()
            msg = dict(line.split("=", 1) for line in data.splitlines() if "=" in line)
            messages.append(msg)
            return msg

        while "READY" not in receive():
            pass
        ready = messages[-1]
        assert ready["READY"] == "1" and ready["MAINPID"] == str(daemon.pid)
        pings = 0
        t0 = time.monotonic()
        while pings < 3:
            if receive().get("WATCHDOG") == "1":
                pings += 1
        # half the 0.3 s period: three pings come within about 0.5 s of each other, well under a second
        assert time.monotonic() - t0 < 5
        code, err = stop_daemon(daemon, signal.SIGTERM)
        assert code == 0, err[-3000:]
        while "STOPPING" not in messages[-1]:
            receive()
    finally:
        if daemon.poll() is None:
            daemon.kill()
            daemon.communicate(timeout=10)
        sock.close()
    assert "signal SIGTERM: stopping" in err
