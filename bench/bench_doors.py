"""Bench: the encoder's samples per second during a capture, alone and under each load a client can make
through the appliance's doors, side by side (same run, same appliance).

The appliance runs in-process on the simulated rig with the simulated encoder (a real pymodbus RTU server on
loopback), time scale 1, OPC UA (user and password, unencrypted endpoint offered) and the web page on. One
capture per row, each the swing of ``CAPTURE`` s; the row's load runs from before the release to after it:

    alone            nothing else
    opcua reads      an authenticated client reading 1,000 nodes per request in a loop
    opcua 4 GB       connections announcing a 4 GB chunk, then zeros, one after the other
    opcua idle       200 connections that never log in (more than max_connections)
    opcua guessing   wrong logins in a loop
    web streams      40 /events streams asked for (more than the slots)
    web pages        4 clients looping on /history

Each load runs in a process of its own (as a client on another machine would: its own CPU is not the
appliance's). A capture that ends in FAULT is shown as not stored (and the FAULT acknowledged).

Run: `.venv/bin/python bench/bench_doors.py` (or `make bench`). Numbers are printed, never asserted.
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing
import os
import socket
import struct
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
os.environ.setdefault("GPIOZERO_PIN_FACTORY", "mock")

CAPTURE = 6.0  # s of swing per capture
#: the flags of the result shown
SHOWN = ("capture_slowed", "encoder_errors")
USER, PASSWORD = "bench", "bench-password-1234"


def _opcua_reads(info: dict, stop) -> None:
    from asyncua import Client

    async def run():
        c = Client(info['endpoint'], timeout=30)
        c.set_user(USER)
        c.set_password(PASSWORD)
        await c.connect()
        try:
            nodes = [c.nodes.server_state] * 1000
            while not stop.is_set():
                await c.read_values(nodes)
        finally:
            await c.disconnect()

    asyncio.run(run())


def _opcua_huge(info: dict, stop) -> None:
    zeros = bytes(65536)
    while not stop.is_set():
        try:
            with socket.create_connection(("127.0.0.1", info['opcua_port']), timeout=5) as s:
                s.sendall(b"HELF" + struct.pack("<I", 0xFFFFFFF0))
                while not stop.is_set():
                    s.sendall(zeros)
        except OSError:
            continue


def _opcua_idle(info: dict, stop) -> None:
    held = []
    try:
        for _ in range(200):
            try:
                held.append(socket.create_connection(("127.0.0.1", info['opcua_port']), timeout=5))
            except OSError:
                break
        stop.wait()
    finally:
        for s in held:
            s.close()


def _opcua_guessing(info: dict, stop) -> None:
    from asyncua import Client

    async def run():
        while not stop.is_set():
            c = Client(info['endpoint'], timeout=30)
            c.set_user(USER)
            c.set_password("wrong")
            try:
                await c.connect()
                await c.disconnect()
            except Exception:
                pass

    asyncio.run(run())


def _web_streams(info: dict, stop) -> None:
    held = []
    try:
        for _ in range(40):
            s = socket.create_connection(("127.0.0.1", info['web_port']), timeout=5)
            s.sendall(b"GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            held.append(s)
        while not stop.is_set():
            for s in held:
                s.setblocking(False)
                with contextlib.suppress(OSError):
                    s.recv(65536)
            stop.wait(0.05)  # a bench's load may pace itself on the wall clock
    finally:
        for s in held:
            s.close()


def _web_pages(info: dict, stop) -> None:
    def reader():
        while not stop.is_set():
            try:
                with urllib.request.urlopen(info['web_url'] + "history", timeout=60) as r:
                    r.read()
            except OSError:
                pass

    threads = [threading.Thread(target=reader, daemon=True) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()


LOADS = {"alone": None, "opcua reads": _opcua_reads, "opcua 4 GB": _opcua_huge, "opcua idle": _opcua_idle,
         "opcua guessing": _opcua_guessing, "web streams": _web_streams, "web pages": _web_pages}


def _doc(state: Path, pw: Path) -> dict:
    return {"device": {"id": "bench", "state_dir": str(state), "log_level": "warning", "store_trace": False},
            "sequencer": {"pre_trigger": 0.2, "capture_duration": CAPTURE, "sample_timeout": 2.0},
            "simulation": {"time_scale": 1.0, "rate": 100.0, "seed": 7, "sensor": "encoder"},
            "modbus": {"enabled": False}, "web": {"host": "127.0.0.1", "port": 0, "enabled": True},
            "opcua": {"host": "127.0.0.1", "port": 0, "username": USER, "password_file": str(pw),
                      "allow_unencrypted": True}}


class Running:
    """The appliance's main loop in a thread; ``press()`` the mock button; ``wait(n)`` for n ended measurements."""

    def __init__(self, app) -> None:
        from _appliance import Finished

        self.app = app
        app.start()
        self.finished = Finished(app)
        self.thread = threading.Thread(target=app.run, daemon=True)
        self.thread.start()

    def press(self) -> None:
        pin = self.app.devices.button.pin
        pin.drive_low()
        pin.drive_high()

    def wait(self, n: int, timeout: float) -> bool:
        return self.finished.wait(n, timeout)

    def stop(self) -> None:
        self.app.request_stop()
        self.thread.join(60)


def main() -> None:
    sys.path.insert(0, str(HERE))
    from service.publish.opcua import guard

    guard.LOCKOUT_AFTER = 10**9  # the guessing row measures the delay, not the lockout
    from service.commands.run import setup_logging

    setup_logging("warning")

    rows = []
    with tempfile.TemporaryDirectory(prefix="moi-bench-doors-") as tmp:
        pw = Path(tmp) / "pw"
        pw.write_text(PASSWORD)
        pw.chmod(0o600)
        from service.config.appliance import parse_config
        from service.daemon import Appliance

        app = Running(Appliance(parse_config(_doc(Path(tmp) / "state", pw), source="bench")))
        try:
            a = app.app
            info = {"endpoint": a.opcua.endpoint, "opcua_port": a.opcua.bound_port, "web_port": a.web.bound_port,
                    "web_url": a.web.url}
            ctx = multiprocessing.get_context("spawn")
            for n, (label, load) in enumerate(LOADS.items(), start=1):
                stop = ctx.Event()
                worker = ctx.Process(target=load, args=(info, stop), daemon=True) if load else None
                if worker is not None:
                    worker.start()
                    time.sleep(2.0)  # let the load get going: a bench may wait on the wall clock
                app.press()
                ok = app.wait(n, CAPTURE * 20)
                stop.set()
                if worker is not None:
                    worker.join(30)
                    if worker.is_alive():
                        worker.kill()
                if app.finished.faults:
                    app.finished.faults = 0
                    a.command("abort", "bench")  # leave the FAULT for the next row
                    ok = False
                m = a.store.latest(None)
                enc = ((m.payload or {}).get("acquisition") or {}).get("encoder") or {} if m is not None else {}
                rows.append((label, "yes" if ok and m is not None and m.status == "ok" else
                             (m.status if m is not None else "none"), enc.get("rate_hz"), enc.get("timeouts"),
                             (m.payload or {}).get("J") if m is not None else None,
                             "" if m is None or m.status == "ok" else (m.error or "")[:60],
                             ",".join(f for f in ((m.payload or {}).get("flags") or []) if f in SHOWN) if m else ""))
        finally:
            app.stop()
    print(f"{'load':16} {'result':>7} {'samples/s':>10} {'timeouts':>9} {'J kg·m²':>12}  flags / why not")
    for label, outcome, rate, timeouts, j, why, flags in rows:
        print(f"{label:16} {outcome:>7} {rate or float('nan'):10.1f} {timeouts or 0:9d} {j or float('nan'):12.6g}  "
              f"{flags or why}")


if __name__ == "__main__":
    main()
