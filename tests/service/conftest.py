"""Fixtures of the service tests: a private Mosquitto on a free loopback port, an MQTT consumer,
free ports, appliance configurations and an in-process appliance runner.

The broker is this fixture's own process (never a system broker on 1883);
its tests are skipped, with the reason, only when the mosquitto binary is
missing.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable

import paho.mqtt.client as mqtt
import pytest
from paho.mqtt.enums import CallbackAPIVersion

from tests.components import missing

MOSQUITTO = shutil.which("mosquitto") or ("/usr/sbin/mosquitto" if os.access("/usr/sbin/mosquitto", os.X_OK) else None)
REPO = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def login_from(source: str, port: int, **form: str) -> Any:
    """The web page's answer (an ``http.client.HTTPResponse``) to a login with ``form`` (``token``, and
    ``user`` for a named one) made from the loopback address ``source`` (127.0.0.2 ...: another client)."""
    import http.client
    import urllib.parse

    def ask(method: str, path: str, body: str = "", cookie: str = "") -> Any:
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=30, source_address=(source, 0))
        c.request(method, path, body=body, headers={"Cookie": cookie,
                                                    "Content-Type": "application/x-www-form-urlencoded"})
        return c.getresponse()

    r = ask("GET", "/")
    csrf = r.read().decode().split('name="csrf-token" content="')[1].split('"')[0]
    return ask("POST", "/login", urllib.parse.urlencode({**form, "csrf": csrf}),
               r.getheader("Set-Cookie", "").split(";")[0])


def wait_until(predicate: Callable[[], Any], timeout: float, interval: float = 0.02, what: str = "condition") -> Any:
    """Poll ``predicate`` (a state owned by another process: a port, a register) until true or fail."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(interval)


def port_open(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


class Broker:
    """A Mosquitto process on 127.0.0.1:port; ``stop()``/``start()`` keep the port.

    persistent: keep client sessions and queued QoS 1 messages across a
    restart (a persistence file in the test's temporary directory), so a
    consumer with a persistent session misses nothing while the broker is down.
    """

    def __init__(self, workdir: Path, persistent: bool = False, listener_lines: list[str] | None = None) -> None:
        self.port = free_port()
        self.workdir = workdir
        self.persistent = persistent
        self.proc: subprocess.Popen | None = None
        self.conf = workdir / "mosquitto.conf"
        lines = [f"listener {self.port} 127.0.0.1"] + (listener_lines or ["allow_anonymous true"])
        if os.geteuid() == 0:
            # mosquitto started as root drops to the 'mosquitto' user, which cannot write our temporary directory
            import pwd
            lines.append(f"user {pwd.getpwuid(os.geteuid()).pw_name}")
        if persistent:
            lines += ["persistence true", f"persistence_location {workdir}/", "autosave_interval 0"]
        else:
            lines += ["persistence false"]
        lines += [f"log_dest file {workdir}/mosquitto.log"]
        self.conf.write_text("\n".join(lines) + "\n")

    def start(self) -> None:
        assert self.proc is None and MOSQUITTO is not None
        proc = self.proc = subprocess.Popen([MOSQUITTO, "-c", str(self.conf)], stdout=subprocess.DEVNULL,
                                            stderr=subprocess.PIPE)
        try:
            wait_until(lambda: port_open(self.port) or proc.poll() is not None, 10, what="mosquitto to listen")
        except AssertionError:
            self.stop()
            raise
        if self.proc.poll() is not None:
            err = self.proc.stderr.read().decode(errors="replace") if self.proc.stderr else ""
            self.proc = None
            raise RuntimeError(f"mosquitto exited at start: {err.strip()}")

    def stop(self) -> None:
        if self.proc is None:
            return
        self.proc.terminate()  # SIGTERM: a persistent broker writes its sessions here
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
        if self.proc.stderr:
            self.proc.stderr.close()
        self.proc = None

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None


def _need_mosquitto() -> None:
    if MOSQUITTO is None:
        missing("mosquitto binary not found (install the Debian package 'mosquitto'; `make test` tries to)")


@pytest.fixture
def broker(tmp_path):
    _need_mosquitto()
    d = tmp_path / "broker"
    d.mkdir()
    b = Broker(d)
    b.start()
    yield b
    b.stop()


@pytest.fixture
def persistent_broker(tmp_path):
    _need_mosquitto()
    d = tmp_path / "pbroker"
    d.mkdir()
    b = Broker(d, persistent=True)
    b.start()
    yield b
    b.stop()


class Consumer:
    """An MQTT subscriber that records what arrives and dedupes results by UUID.

    persistent: a persistent session (clean_session False, QoS 1) so that the
    broker queues results while the consumer is away.
    """

    def __init__(self, port: int, topics: list[str], client_id: str = "test-consumer", persistent: bool = False) -> None:
        self.messages: list[tuple[str, bytes, bool]] = []
        self._cond = threading.Condition()
        self._subscribed = threading.Event()
        self.topics = topics
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=client_id, clean_session=not persistent)
        self.client.reconnect_delay_set(0.1, 0.5)  # type: ignore[arg-type]  # s; paho's hints say int, it takes float
        self.client.on_connect = self._on_connect
        self.client.on_subscribe = lambda *a: self._subscribed.set()
        self.client.on_message = self._on_message
        self.client.connect_async("127.0.0.1", port, keepalive=10)
        self.client.loop_start()

    def _on_connect(self, client, userdata, flags, rc, props) -> None:
        if not rc.is_failure:
            client.subscribe([(t, 1) for t in self.topics])

    def _on_message(self, client, userdata, msg) -> None:
        with self._cond:
            self.messages.append((msg.topic, bytes(msg.payload), bool(msg.retain)))
            self._cond.notify_all()

    def wait_subscribed(self, timeout: float = 10) -> None:
        assert self._subscribed.wait(timeout), "consumer not subscribed"

    def on(self, topic_suffix: str) -> list[bytes]:
        with self._cond:
            return [p for t, p, _ in self.messages if t.endswith(topic_suffix)]

    def results(self) -> list[dict]:
        return [json.loads(p) for p in self.on("/result")]

    def unique_results(self) -> dict[str, dict]:
        """Results deduped by UUID (what a consumer must do with QoS 1)."""
        out: dict[str, dict] = {}
        for r in self.results():
            out.setdefault(r["uuid"], r)
        return out

    def wait(self, predicate: Callable[["Consumer"], bool], timeout: float, what: str = "messages") -> None:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not predicate(self):
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"timed out after {timeout} s waiting for {what}; got {self.messages!r:.2000}")
                self._cond.wait(left)

    def publish(self, topic: str, payload: str, retain: bool = False) -> None:
        self.client.publish(topic, payload, qos=1, retain=retain).wait_for_publish(5)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


@pytest.fixture
def consumer_factory():
    made: list[Consumer] = []

    def make(port: int, topics: list[str], **kwargs: Any) -> Consumer:
        c = Consumer(port, topics, **kwargs)
        made.append(c)
        return c

    yield make
    for c in made:
        c.close()


def appliance_doc(state_dir: Path, *, mqtt_port: int | None = None, modbus_port: int = 0,
                  device_id: str = "test-rig", time_scale: float = 20.0, **extra: dict) -> dict:
    """A configuration document for a fast simulated appliance (an 8 s swing in about 0.4 s).

    The capture is long enough for five swings: on a loaded host the release can come a few hundred
    milliseconds of real time late, seconds of simulated time at this scale, and three whole swings must
    still be left for the fit."""
    doc: dict[str, Any] = {
        "device": {"id": device_id, "state_dir": str(state_dir), "log_level": "info"},
        "sequencer": {"pre_trigger": 0.2, "capture_duration": 8.0, "sample_timeout": 2.0},
        # the in-process sensor by default (fast); tests of the full encoder link ask for sensor = "encoder"
        "simulation": {"time_scale": time_scale, "rate": 100.0, "seed": 7, "sensor": "direct",
                       "effects": {"viscous": {"c": 1.5e-4}}},
        "modbus": {"host": "127.0.0.1", "port": modbus_port},
        # the web page only where a test asks for it (web={"enabled": True}); on a free port then
        "web": {"host": "127.0.0.1", "port": 0, "enabled": False},
    }
    if mqtt_port is not None:
        doc["mqtt"] = {"host": "127.0.0.1", "port": mqtt_port, "reconnect_min": 0.1, "reconnect_max": 0.5,
                       "keepalive": 5}
    for table, values in extra.items():
        doc.setdefault(table, {}).update(values)
    return doc


def write_toml(path: Path, doc: dict) -> Path:
    import tomli_w
    path.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return path


class RunningAppliance:
    """An Appliance running its main loop in a thread (in-process: the mock button is reachable)."""

    def __init__(self, doc: dict, **kwargs: Any) -> None:
        from service.config.appliance import parse_config
        from service.daemon import Appliance

        self.config = parse_config(doc, source="test.toml")
        self.app = Appliance(self.config, **kwargs)
        self.app.start()
        self.events: list = []
        self._cond = threading.Condition()
        seq = self.app.sequencer
        assert seq is not None  # made by start()
        seq.subscribe(self._on_event)
        self.thread = threading.Thread(target=self.app.run, name="test-appliance-main", daemon=True)
        self.thread.start()

    def _on_event(self, event) -> None:
        with self._cond:
            self.events.append(event)
            self._cond.notify_all()

    def states(self) -> list[str]:
        with self._cond:
            return [e.state.value for e in self.events]

    def wait_event(self, predicate: Callable[[Any], bool], timeout: float, count: int = 1, what: str = "event") -> None:
        """Wait until ``count`` sequencer events satisfy ``predicate``."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while sum(1 for e in self.events if predicate(e)) < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"timed out after {timeout} s waiting for {what}; states {self.states()}")
                self._cond.wait(left)

    def wait_done(self, count: int, timeout: float = 30) -> None:
        """Wait until ``count`` measurements ended and the sequencer is back in IDLE."""
        self.wait_event(lambda e: e.state.value == "IDLE" and e.previous.value in ("PUBLISHING", "ABORTED"),
                        timeout, count, f"{count} measurement(s) back to IDLE")

    def press(self) -> None:
        devices = self.app.devices
        assert devices is not None and devices.button is not None
        pin = devices.button.pin
        pin.drive_low()
        pin.drive_high()

    def stop(self) -> int:
        self.app.request_stop()
        self.thread.join(30)
        assert not self.thread.is_alive(), "appliance did not stop"
        return self.app.exit_status


@pytest.fixture
def appliance_factory():
    running: list[RunningAppliance] = []

    def make(doc: dict, **kwargs: Any) -> RunningAppliance:
        r = RunningAppliance(doc, **kwargs)
        running.append(r)
        return r

    yield make
    for r in running:
        if r.thread.is_alive():
            r.stop()


def moi_subprocess(args: list[str], env_extra: dict | None = None, **kwargs: Any) -> subprocess.Popen:
    """`moi ARGS` in a child process (the daemon as systemd runs it)."""
    env = dict(os.environ)
    env["GPIOZERO_PIN_FACTORY"] = "mock"
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.update(env_extra or {})
    return subprocess.Popen([sys.executable, "-m", "service.cli", *args], cwd=str(REPO), env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)
