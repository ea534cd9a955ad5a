"""Bench: time from the end of identification to the result being readable over Modbus and received over MQTT.

The appliance runs in-process on the simulated rig (in-process sensor, time
sped up) with its Modbus server on a loopback port and a private Mosquitto on
another (skipped, with a note, when the mosquitto binary is missing). For each
measurement:

    t0  the identification returns (stamped by the identifier seam)
    t1  the result is committed to the store (the sink)
    t2  a PLC client reading `seq` in a tight loop over Modbus TCP sees the new value
    t3  an MQTT subscriber on loopback receives the result

Run: `.venv/bin/python bench/bench_service.py` (or `make bench`). Numbers are
printed, never asserted.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
os.environ.setdefault("GPIOZERO_PIN_FACTORY", "mock")

N = 12


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_broker(workdir: Path) -> tuple[subprocess.Popen | None, int | None]:
    exe = shutil.which("mosquitto") or ("/usr/sbin/mosquitto" if os.access("/usr/sbin/mosquitto", os.X_OK) else None)
    if exe is None:
        return None, None
    port = _free_port()
    conf = workdir / "mosquitto.conf"
    lines = [f"listener {port} 127.0.0.1", "allow_anonymous true", "persistence false"]
    if os.geteuid() == 0:
        import pwd
        lines.append(f"user {pwd.getpwuid(0).pw_name}")
    conf.write_text("\n".join(lines) + "\n")
    proc = subprocess.Popen([exe, "-c", str(conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return proc, port
        except OSError:
            time.sleep(0.02)
    proc.kill()
    return None, None


def _pct(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q * (len(xs) - 1))))]


def main() -> None:
    import paho.mqtt.client as mqtt
    from _appliance import Finished, StampedIdentifier, simulated_doc
    from paho.mqtt.enums import CallbackAPIVersion
    from pymodbus.client import ModbusTcpClient

    from service.config.appliance import parse_config
    from service.daemon import Appliance
    from service.publish.modbus import registers as R
    from service.recording import Recorder

    work = Path(tempfile.mkdtemp(prefix="moi-bench-service-"))
    broker, mqtt_port = _start_broker(work)
    doc = simulated_doc(work / "state")
    if mqtt_port:
        doc["mqtt"] = {"host": "127.0.0.1", "port": mqtt_port}
    else:
        print("note: mosquitto not found; MQTT timing skipped")
    import logging
    logging.basicConfig(level=logging.WARNING)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

    t_stored: dict[int, float] = {}

    class StampedRecorder(Recorder):
        """Stamps the moment the store committed (bench instrumentation only)."""

        def _note_stored(self, uuid: str) -> None:
            t_stored[len(t_stored) + 1] = time.perf_counter()
            super()._note_stored(uuid)

    config = parse_config(doc, source="bench")
    stamped = StampedIdentifier(config.identification)
    t_ident = stamped.stamps
    app = Appliance(config, identifier=stamped, poll_interval=0.02)
    app.recorder = StampedRecorder(app)
    app.start()
    main_loop = threading.Thread(target=app.run, daemon=True)
    main_loop.start()

    t_mqtt: dict[str, float] = {}
    seq_of_uuid: dict[str, int] = {}
    mqtt_cond = threading.Condition()
    sub = None
    if mqtt_port:
        sub = mqtt.Client(CallbackAPIVersion.VERSION2, client_id="bench-consumer")
        subscribed = threading.Event()
        sub.on_connect = lambda c, u, f, rc, p: c.subscribe("moi/bench/result", 1)
        sub.on_subscribe = lambda *a: subscribed.set()

        def on_message(c, u, msg):
            now = time.perf_counter()
            d = json.loads(msg.payload)
            with mqtt_cond:
                t_mqtt.setdefault(d["uuid"], now)
                seq_of_uuid[d["uuid"]] = d["seq"]
                mqtt_cond.notify_all()

        sub.on_message = on_message
        sub.connect("127.0.0.1", mqtt_port)
        sub.loop_start()
        subscribed.wait(10)
        app.mqtt.connected_event.wait(10)

    # the PLC: reads `seq` back to back and stamps every change
    t_modbus: dict[int, float] = {}
    stop = threading.Event()
    reads = [0]

    def plc():
        c = ModbusTcpClient("127.0.0.1", port=app.modbus.bound_port, timeout=3)
        c.connect()
        last = 0
        while not stop.is_set():
            rr = c.read_input_registers(R.SNAPSHOT_START, count=1, device_id=1)
            reads[0] += 1
            s = rr.registers[0]
            if s != last:
                t_modbus[s] = time.perf_counter()
                last = s
        c.close()

    reader = threading.Thread(target=plc, daemon=True)
    reader.start()
    finished = Finished(app)
    t_wall0 = time.perf_counter()
    for i in range(1, N + 1):
        app.command("trigger", "bench")
        finished.wait(i, 60)
    if sub is not None:
        with mqtt_cond:
            mqtt_cond.wait_for(lambda: len(t_mqtt) >= N, 30)
    wall = time.perf_counter() - t_wall0
    stop.set()
    reader.join(5)
    app.request_stop()
    main_loop.join(30)
    if sub is not None:
        sub.disconnect()
        sub.loop_stop()
    if broker is not None:
        broker.terminate()
        broker.wait(10)
    shutil.rmtree(work, ignore_errors=True)

    ms = 1e3
    store = [(t_stored[i] - t_ident[i]) * ms for i in range(1, N + 1) if i in t_stored and i in t_ident]
    modbus = [(t_modbus[i] - t_ident[i]) * ms for i in range(1, N + 1) if i in t_modbus and i in t_ident]
    print(f"{N} measurements on the simulated rig (5 s swings × 25), {wall:.1f} s wall; "
          f"PLC loop made {reads[0]} Modbus reads ({reads[0] / wall:.0f}/s)")
    print("latency from the end of identification, ms        median     p90     max")
    print(f"  result committed to the store (SQLite, WAL)   {statistics.median(store):8.2f} {_pct(store, .9):7.2f} {max(store):7.2f}")
    print(f"  readable over Modbus TCP (PLC sees new seq)   {statistics.median(modbus):8.2f} {_pct(modbus, .9):7.2f} {max(modbus):7.2f}")
    if t_mqtt:
        mq = [(t - t_ident[seq_of_uuid[u]]) * ms for u, t in t_mqtt.items() if seq_of_uuid[u] in t_ident]
        print(f"  received over MQTT (QoS 1, loopback broker)   {statistics.median(mq):8.2f} {_pct(mq, .9):7.2f} {max(mq):7.2f}")


if __name__ == "__main__":
    main()
