"""MQTT with TLS and a username/password (password from a file) against a real Mosquitto."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from service.config.appliance import parse_config
from service.persistence.store import Store
from service.publish.mqtt.client import MqttService
from tests.components import missing
from tests.service.conftest import MOSQUITTO, Broker, wait_until

pytestmark = pytest.mark.broker


def _openssl(*args: str, cwd) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


@pytest.fixture
def tls_broker(tmp_path):
    if MOSQUITTO is None:
        missing("mosquitto binary not found (the Debian package 'mosquitto'; `make test` tries to install it)")
    if shutil.which("openssl") is None or shutil.which("mosquitto_passwd") is None:
        missing("openssl or mosquitto_passwd not found (needed to make a test CA and password file)")
    d = tmp_path / "tls"
    d.mkdir()
    _openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-days", "2",
             "-subj", "/CN=moi test CA", "-keyout", "ca.key", "-out", "ca.pem", cwd=d)
    _openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-subj", "/CN=localhost",
             "-keyout", "server.key", "-out", "server.csr", cwd=d)
    (d / "san.ext").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    _openssl("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-days", "2",
             "-extfile", "san.ext", "-out", "server.pem", cwd=d)
    subprocess.run(["mosquitto_passwd", "-b", "-c", str(d / "passwd"), "moi-01", "s3cret"], check=True,
                   capture_output=True, timeout=30)
    (d / "passwd").chmod(0o600)
    b = Broker(d, listener_lines=[
        "allow_anonymous false", f"password_file {d / 'passwd'}",
        f"cafile {d / 'ca.pem'}", f"certfile {d / 'server.pem'}", f"keyfile {d / 'server.key'}",
    ])
    b.start()
    b.dir = d  # type: ignore[attr-defined]
    yield b
    b.stop()


def _settings(tmp_path, broker, password: str):
    pw = tmp_path / "mqtt-password"
    pw.write_text(password + "\n")
    doc = {"device": {"id": "tls-rig", "state_dir": str(tmp_path / "state")},
           "mqtt": {"host": "localhost", "port": broker.port, "tls": True, "ca_file": str(broker.dir / "ca.pem"),
                    "username": "moi-01", "password_file": str(pw), "reconnect_min": 0.1, "reconnect_max": 0.5}}
    return parse_config(doc, source="tls.toml")


def test_results_go_out_over_tls_with_a_password_from_a_file(tmp_path, tls_broker):
    cfg = _settings(tmp_path, tls_broker, "s3cret")
    store = Store(cfg.state_dir)
    m = store.record(status="ok", trigger="test", device_id="tls-rig", software_version="0", started_at=1.0,
                     finished_at=2.0, result={}, build_payload=lambda u, s: {"uuid": u, "seq": s}, enqueue={"mqtt": ("result",)})
    svc = MqttService(cfg.mqtt, cfg.device_id, store)
    svc.start()
    try:
        assert svc.connected_event.wait(15), svc.last_error
        assert svc.sender.wait_empty(15)
        assert store.get(m.uuid).published_at is not None
    finally:
        svc.stop()
        store.close()


def test_a_wrong_password_is_reported_and_nothing_leaves_the_outbox(tmp_path, tls_broker):
    cfg = _settings(tmp_path, tls_broker, "wrong")
    store = Store(cfg.state_dir)
    store.record(status="ok", trigger="test", device_id="tls-rig", software_version="0", started_at=1.0,
                 finished_at=2.0, result={}, build_payload=lambda u, s: {"uuid": u, "seq": s}, enqueue={"mqtt": ("result",)})
    svc = MqttService(cfg.mqtt, cfg.device_id, store)
    svc.start()
    try:
        wait_until(lambda: svc.last_error, 15, what="the broker's refusal")
        assert "refused" in (svc.last_error or "") and not svc.is_connected
        assert store.outbox_count() == 1
    finally:
        svc.stop()
        store.close()
