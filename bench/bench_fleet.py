"""Bench: a fleet of five appliances on one broker, with a Sparkplug host and an MQTT subscriber.

Five `moi run` daemons on the simulated rig, each with its own device id, state directory and Modbus
port, publish over MQTT and as Sparkplug B edge nodes (primary host configured) to one Mosquitto. A
PLC-like client per appliance triggers measurements over Modbus one after the other; meanwhile the broker
is restarted a few times under them. A Sparkplug host application (decoding with pysparkplug) and an MQTT
subscriber, both with persistent sessions, count what arrives. At the end, per appliance: results stored,
received by each (unique), lost (stored, never received) and duplicated (received more than once), the
message rate the broker carried, and the broker's memory (resident, peak over the run).

Run: `.venv/bin/python bench/bench_fleet.py` (or `make bench`); FLEET_N sets the measurements per
appliance (default 40), FLEET_RESTARTS the broker restarts (default 3). Numbers are printed, never
asserted.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
os.environ.setdefault("GPIOZERO_PIN_FACTORY", "mock")

APPLIANCES = 5
N = int(os.environ.get("FLEET_N", "40"))
RESTARTS = int(os.environ.get("FLEET_RESTARTS", "3"))


def _rss_kib(pid: int, field: str = "VmRSS") -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


class Subscriber:
    """An MQTT consumer of every appliance's results (persistent session, QoS 1)."""

    def __init__(self, port: int) -> None:
        import paho.mqtt.client as mqtt
        from paho.mqtt.enums import CallbackAPIVersion

        self.got: list[tuple[str, str]] = []  # (device, uuid)
        self.messages = 0
        self._lock = threading.Lock()
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id="fleet-historian", clean_session=False)
        self.client.reconnect_delay_set(0.1, 0.5)  # type: ignore[arg-type]
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe("moi/+/result", qos=1)
        self.client.on_message = self._on_message
        self.client.connect_async("127.0.0.1", port, keepalive=10)
        self.client.loop_start()

    def _on_message(self, client, userdata, msg) -> None:
        doc = json.loads(msg.payload)
        with self._lock:
            self.messages += 1
            self.got.append((doc["device_id"], doc["uuid"]))

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def _daemon(cfg: Path, log: Path) -> subprocess.Popen:
    env = dict(os.environ, GPIOZERO_PIN_FACTORY="mock",
               PYTHONPATH=str(HERE.parent) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    with open(log, "ab") as err:
        return subprocess.Popen([sys.executable, "-m", "service.cli", "run", "--config", str(cfg)], cwd=str(HERE.parent),
                                env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err)


def _up(port: int, daemon: subprocess.Popen) -> bool:
    from tests.service.conftest import port_open
    return port_open(port) or daemon.poll() is not None


def _coil(port: int, name: str) -> None:
    """Write one command coil of an appliance's Modbus map, as a PLC does."""
    from pymodbus.client import ModbusTcpClient

    from service.publish.modbus import registers as R
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=3, retries=0)
    assert c.connect()
    try:
        assert not c.write_coil(R.COILS[name], True, device_id=1).isError()
    finally:
        c.close()


def _plc(name: str, port: int, faults: Counter, errors: list[str]) -> None:
    """Like a PLC: trigger, wait for the end; a FAULT (a starved simulated capture on a loaded
    machine) is acknowledged and counted, and the next one triggered."""
    from service.publish.modbus import registers as R
    from tests.service.conftest import wait_until
    from tests.service.test_service_process import read_snapshot

    idle, fault = R.STATE_CODES["IDLE"], R.STATE_CODES["FAULT"]
    try:
        for n in range(1, N + 1):
            _coil(port, "trigger")
            def ended(n: int = n) -> Any:
                s = read_snapshot(port)
                return s and s["measurements_started"] == n and s["state"] in (idle, fault) and s

            s = wait_until(ended, 300, 0.05, f"{name} measurement {n}")
            if s["state"] == fault:
                faults[name] += 1
                _coil(port, "abort")
                wait_until(lambda: (s := read_snapshot(port)) and s["state"] == idle, 60, 0.05,
                           f"{name} back to IDLE")
    except Exception as exc:
        errors.append(f"{name}: {exc}")


def _restarter(sub: Any, broker: Any, peak: list[int], done: threading.Event) -> None:
    """Restarts of the broker spread over the run (by the fleet's progress, read from the subscriber's count)."""
    for k in range(1, RESTARTS + 1):
        target = k * APPLIANCES * N // (RESTARTS + 1)
        while len(sub.got) < target and not done.is_set():
            peak.append(_rss_kib(broker.proc.pid) if broker.proc else 0)
            done.wait(0.2)
        if done.is_set():
            return
        peak.append(_rss_kib(broker.proc.pid, "VmHWM") if broker.proc else 0)
        broker.stop()
        done.wait(1.0)  # the broker stays down a second: results pile up in the outboxes
        broker.start()


def main() -> None:
    from tests.service.conftest import MOSQUITTO, Broker, appliance_doc, free_port, wait_until, write_toml

    try:
        from tests.service.publish.sparkplug.sparkplug_host import SparkplugHost
    except BaseException as exc:  # pytest's importorskip raises its Skipped, not an ImportError
        print(f"skipped: the Sparkplug host needs pysparkplug (`make install`): {exc}")
        return
    if MOSQUITTO is None:
        print("skipped: no mosquitto binary")
        return

    with tempfile.TemporaryDirectory(prefix="moi-fleet-") as tmp:
        root = Path(os.environ.get("FLEET_DIR") or tmp)  # FLEET_DIR: keep the logs and stores there
        (root / "broker").mkdir()
        broker = Broker(root / "broker", persistent=True)
        broker.start()
        host = SparkplugHost(broker.port, host_id="fleet-scada", persistent=True)
        host.online()
        sub = Subscriber(broker.port)
        names = [f"line-{i + 1}" for i in range(APPLIANCES)]
        ports = {name: free_port() for name in names}
        daemons = {}
        for name in names:
            doc = appliance_doc(root / name, mqtt_port=broker.port, modbus_port=ports[name], device_id=name,
                                sparkplug={"host": "127.0.0.1", "port": broker.port, "primary_host": "fleet-scada",
                                           "reconnect_min": 0.1, "reconnect_max": 0.5, "keepalive": 5})
            doc["simulation"]["time_scale"] = 10.0  # five daemons share the cores: a 5 s swing in 0.5 s
            daemons[name] = _daemon(write_toml(root / f"{name}.toml", doc), root / f"{name}.log")
        for name in names:
            wait_until(functools.partial(_up, ports[name], daemons[name]), 120, what=f"{name} up")
        host.wait(lambda h: h.count("DBIRTH") >= APPLIANCES, 60, "every appliance's DBIRTH")

        peak = [_rss_kib(broker.proc.pid)]  # type: ignore[union-attr]
        done = threading.Event()
        errors: list[str] = []

        faults: Counter = Counter()

        t0 = time.monotonic()
        threads = [threading.Thread(target=_plc, args=(n, ports[n], faults, errors)) for n in names]
        threads.append(threading.Thread(target=_restarter, args=(sub, broker, peak, done)))
        for t in threads:
            t.start()
        for t in threads[:-1]:
            t.join()
        measured = time.monotonic() - t0
        done.set()
        threads[-1].join()
        total = APPLIANCES * N - sum(faults.values())  # a FAULT has no result
        try:
            wait_until(lambda: len({u for _, u in sub.got}) >= total
                       and len({r["Result/UUID"] for r in host.results()}) >= total, 180, 0.2, "every result")
        except AssertionError as exc:
            print(f"NOT ALL DELIVERED: {exc}")
        elapsed = time.monotonic() - t0
        peak.append(_rss_kib(broker.proc.pid, "VmHWM") if broker.proc else 0)

        from service.persistence.store import Store
        stored: dict[str, list[str]] = {}
        backlog = 0
        for name in names:
            with Store(root / name, read_only=True) as store:
                stored[name] = [m.uuid for m in store.list(limit=None, status="ok")]
                backlog += store.outbox_count()
        for d in daemons.values():
            d.terminate()
        for d in daemons.values():
            d.wait(30)
        spb_counts = Counter((r["_device"], r["Result/UUID"]) for r in host.results())
        mqtt_counts = Counter(sub.got)
        print(f"{APPLIANCES} appliances × {N} measurements, broker restarted {RESTARTS} times; "
              f"measuring took {measured:.0f} s, all delivered after {elapsed:.0f} s")
        print(f"{'appliance':<10} {'faults':>6} {'stored':>6} | {'Sparkplug':>9} {'lost':>4} {'dup':>4} | {'MQTT':>5} {'lost':>4} {'dup':>4}")
        tot: Counter = Counter()
        for name in names:
            s = set(stored[name])
            sp = {u: c for (d, u), c in spb_counts.items() if d == name}
            mq = {u: c for (d, u), c in mqtt_counts.items() if d == name}
            row = dict(stored=len(s), sp=len(sp.keys() & s), sp_lost=len(s - sp.keys()),
                       sp_dup=sum(c - 1 for c in sp.values()), mq=len(mq.keys() & s), mq_lost=len(s - mq.keys()),
                       mq_dup=sum(c - 1 for c in mq.values()))
            tot.update(row)
            print(f"{name:<10} {faults[name]:>6} {row['stored']:>6} | {row['sp']:>9} {row['sp_lost']:>4} {row['sp_dup']:>4} | "
                  f"{row['mq']:>5} {row['mq_lost']:>4} {row['mq_dup']:>4}")
        print(f"{'all':<10} {sum(faults.values()):>6} {tot['stored']:>6} | {tot['sp']:>9} {tot['sp_lost']:>4} {tot['sp_dup']:>4} | "
              f"{tot['mq']:>5} {tot['mq_lost']:>4} {tot['mq_dup']:>4}")
        msgs = len(host.received) + sub.messages
        print(f"messages received by the host and the subscriber: {msgs} ({msgs / elapsed:.1f}/s over the run; "
              f"results {2 * total / measured:.1f}/s while measuring); outbox rows left: {backlog}")
        print(f"broker resident memory: peak {max(peak) / 1024:.1f} MiB; host decoding errors: {len(host.errors)}; "
              f"PLC errors: {errors or 'none'}")
        host.close()
        sub.close()
        broker.stop()


if __name__ == "__main__":
    main()
