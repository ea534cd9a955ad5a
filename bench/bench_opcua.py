"""Bench: the OPC UA server's start time, and the time from the end of identification to the ResultReadyEvent
at a client.

1. Start time of the server alone (certificate made, address space built with the companion specifications'
   types, listening), three ways, RUNS times each (medians): cold, the first start of a state directory (it
   makes the certificate and asyncua's cache of the standard address space); warm, a later start that reads
   that cache; and a start without a cache (the standard address space built from code). asyncua keeps the
   cache with Python's ``shelve``; the server uses it only where dbm has a real backend (gdbm, ndbm:
   Debian/Raspberry Pi OS python3-gdbm), with dbm.dumb alone it builds (faster than reading dbm.dumb): then
   warm is a start without a cache too. Each start runs in a process of its own; its CPU time (all threads)
   is printed beside the wall-clock time, as the steadier number on a machine that others share.
2. The daemon on the simulated rig with the OPC UA server; an asyncua client (Basic256Sha256 Sign & Encrypt,
   user and password) subscribed to the ResultReadyEvent. For each of N measurements:

       t0  the identification returns (stamped by the identifier seam)
       t1  the client's subscription handler receives the event

Run: `.venv/bin/python bench/bench_opcua.py` (or `make bench`). Numbers are printed, never asserted.
"""

from __future__ import annotations

import asyncio
import dbm
import os
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

N = 8
RUNS = 3  # starts per case (medians)
USER, PASSWORD = "bench", "bench-password"


def _one_start(state: str, cache: str | None) -> None:
    """One server start in this process (``--one-start``): prints the start time and the types' share, s."""
    from service.publish.opcua.server import OpcUaServer
    from service.publish.opcua.settings import OpcUaSettings

    server = OpcUaServer(OpcUaSettings(port=0, username=USER, password=PASSWORD, cache_file=cache), "bench",
                         Path(state), software_version="bench")
    cpu = time.process_time()
    server.start()
    cpu = time.process_time() - cpu  # all threads of this process: what the start costs, whatever else runs
    server.stop()
    print(server.start_seconds, cpu, server.types_seconds)


def _start_times(work: Path) -> None:
    """Each start in a process of its own, as the appliance starts (no address space of an earlier start
    left in memory for the garbage collector to walk)."""
    def start(state: Path, cache: Path | None = None) -> tuple[float, float, float]:
        args = [sys.executable, __file__, "--one-start", str(state)] + ([str(cache)] if cache else [])
        out = subprocess.run(args, check=True, capture_output=True, text=True).stdout.split()
        return float(out[-3]), float(out[-2]), float(out[-1])

    cold, warm, uncached = [], [], []
    for i in range(RUNS):
        state = work / f"state-{i}"
        cold.append(start(state))  # a new state directory: makes the certificate and the cache
        warm.append(start(state))  # reads them
        uncached.append(start(state, work / f"none-{i}" / "x"))  # the standard address space built from code
        for p in (work / f"none-{i}").glob("*"):
            p.unlink()
    for label, runs in (("cold (first start: makes the certificate and the cache)", cold),
                        ("warm (reads the cache)", warm), ("without a cache (builds from code)", uncached)):
        print(f"OPC UA server start, {label}: median {statistics.median(r[0] for r in runs):.2f} s of {RUNS} "
              f"(CPU {statistics.median(r[1] for r in runs):.2f} s; the companion types "
              f"{1000 * statistics.median(r[2] for r in runs):.0f} ms)")
    from service.publish.opcua.server import fast_dbm

    backend = dbm.whichdb(str(work / "state-0" / "opcua" / "address-space")) if fast_dbm() else None
    print(f"  (the cache: {backend or 'not used, this Python has dbm.dumb only'})")


def main() -> None:
    import logging

    from _appliance import Finished, StampedIdentifier, simulated_doc
    from asyncua import Client, ua
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
    from cryptography.x509.oid import ExtendedKeyUsageOID

    from service.config.appliance import parse_config
    from service.daemon import Appliance
    from service.publish.opcua.model import NS_MACHINERY, NS_MOI, NS_RESULT

    logging.basicConfig(level=logging.WARNING)
    for name in ("asyncua", "pymodbus"):
        logging.getLogger(name).setLevel(logging.ERROR)
    work = Path(tempfile.mkdtemp(prefix="moi-bench-opcua-"))
    _start_times(work / "start")

    pw = work / "password"
    pw.write_text(PASSWORD, encoding="utf-8")
    doc = simulated_doc(work / "state")
    doc["opcua"] = {"host": "127.0.0.1", "port": 0, "username": USER, "password_file": str(pw)}
    config = parse_config(doc, source="bench")
    stamped = StampedIdentifier(config.identification)
    t_ident = stamped.stamps
    app = Appliance(config, identifier=stamped, poll_interval=0.02)
    app.start()
    print(f"OPC UA server in the daemon: started in {app.opcua.start_seconds:.2f} s (first start of this state "
          "directory)")
    finished = Finished(app)
    main_loop = threading.Thread(target=app.run, daemon=True)
    main_loop.start()
    t_event: list[float] = []
    key, cert = work / "client-key.pem", work / "client-cert.der"

    class Handler:
        def __init__(self, loop_event: asyncio.Event) -> None:
            self.arrived = loop_event

        def event_notification(self, event) -> None:
            t_event.append(time.perf_counter())
            self.arrived.set()

    async def client() -> None:
        await setup_self_signed_certificate(key, cert, "urn:moi-bench:client", "localhost",
                                            [ExtendedKeyUsageOID.CLIENT_AUTH], {"commonName": "bench"})
        c = Client(app.opcua.endpoint, timeout=10)
        c.application_uri = "urn:moi-bench:client"
        await c.set_security(SecurityPolicyBasic256Sha256, str(cert), str(key),
                             mode=ua.MessageSecurityMode.SignAndEncrypt)
        c.set_user(USER)
        c.set_password(PASSWORD)
        async with c:
            ns = {u: await c.get_namespace_index(u) for u in (NS_MACHINERY, NS_MOI, NS_RESULT)}
            rm = await c.nodes.objects.get_child([f"{ns[NS_MACHINERY]}:Machines", f"{ns[NS_MOI]}:bench",
                                                  f"{ns[NS_MACHINERY]}:MachineryBuildingBlocks",
                                                  f"{ns[NS_RESULT]}:ResultManagement"])
            etype = await c.nodes.base_event_type.get_child(f"{ns[NS_RESULT]}:ResultReadyEventType")
            arrived = asyncio.Event()
            sub = await c.create_subscription(10, Handler(arrived))
            await sub.subscribe_events(rm, etype)
            for i in range(1, N + 1):
                arrived.clear()
                app.command("trigger", "bench")
                await asyncio.wait_for(arrived.wait(), 60)
                await asyncio.to_thread(finished.wait, i, 60)

    try:
        asyncio.run(client())
    finally:
        app.request_stop()
        main_loop.join(30)
    lat = [1000 * (t_event[i] - t_ident[i + 1]) for i in range(min(len(t_event), len(t_ident)))]
    if lat:
        print(f"end of identification → ResultReadyEvent at the client (subscription publishing interval 10 ms), "
              f"{len(lat)} results: median {statistics.median(lat):.1f} ms, max {max(lat):.1f} ms")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--one-start"]:
        _one_start(sys.argv[2], sys.argv[3] if len(sys.argv) > 3 else None)
    else:
        main()
