"""Bench: page load of a result (its HTML and its plot) on the appliance's web page, 1,000 measurements stored.

The appliance runs in-process on the simulated rig with the web page on a
loopback port. One real measurement is made (its plot drawn and kept), then
the store is filled to 1,000 measurements, each with its result payload, raw
trace and plot, as the daemon keeps them. Timed, from a client on loopback,
each a new connection as a browser's first visit:

    result page  GET /results/<uuid> (HTML) + GET /results/<uuid>/plot.png, of random measurements
    history      GET /history (the newest page) and a filtered, later page

Goal: a result page (HTML + plot) in at most 200 ms. Run:
`.venv/bin/python bench/bench_web.py` (or `make bench`). Numbers are printed, never asserted.
"""

from __future__ import annotations

import os
import random
import statistics
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
os.environ.setdefault("GPIOZERO_PIN_FACTORY", "mock")

STORED = 1000
LOADS = 40


def _get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=30) as r:
        return r.read()


def main() -> None:
    from service.config.appliance import parse_config
    from service.daemon import Appliance
    from service.publish.web.server import PLOT_NAME

    with tempfile.TemporaryDirectory(prefix="moi-bench-web-") as state:
        doc = {"device": {"id": "bench", "state_dir": state, "log_level": "warning"},
               "sequencer": {"pre_trigger": 0.2, "capture_duration": 20.0, "sample_timeout": 2.0},
               "simulation": {"time_scale": 40.0, "rate": 200.0, "seed": 3, "sensor": "direct"},
               "modbus": {"enabled": False}, "web": {"host": "127.0.0.1", "port": 0}}
        app = Appliance(parse_config(doc, source="bench"))
        app.start()
        store = app.store
        assert store is not None, "start() opens the store"
        import threading
        main_loop = threading.Thread(target=app.run, daemon=True)
        main_loop.start()
        try:
            app.command("trigger", "bench")
            if not app.wait_stored(1, 120):
                raise RuntimeError("the simulated measurement did not finish")
            first = store.latest()
            base = app.web.url.rstrip("/")
            _get(f"{base}/results/{first.uuid}/plot.png")  # waits for the plot worker
            png, media = store.get_attachment(first.uuid, PLOT_NAME)
            full = store.get(first.uuid, trace=True)
            t0 = time.perf_counter()
            uuids = [first.uuid]
            for i in range(STORED - 1):
                m = store.record(
                    status="ok", trigger="bench", device_id="bench", software_version=full.software_version,
                    started_at=full.started_at - 60.0 * (i + 1), finished_at=full.finished_at - 60.0 * (i + 1),
                    result=full.payload, build_payload=lambda uuid, seq: {**full.payload, "uuid": uuid, "seq": seq},
                    rig=full.rig, config=full.config, trace_t=full.trace_t, trace_angle=full.trace_angle,
                    trace_meta=full.trace_meta)
                store.put_attachment(m.uuid, PLOT_NAME, png, media)
                uuids.append(m.uuid)
            fill = time.perf_counter() - t0
            db = Path(state) / "results.db"
            print(f"store: {store.count()} measurements with trace ({len(full.trace_t)} samples) and plot "
                  f"({len(png) / 1e3:.0f} kB) each, {db.stat().st_size / 1e6:.0f} MB; filled in {fill:.1f} s")
            rng = random.Random(1)
            page, html, plot = [], [], []
            for _ in range(LOADS):
                uid = rng.choice(uuids)
                a = time.perf_counter()
                body = _get(f"{base}/results/{uid}")
                b = time.perf_counter()
                image = _get(f"{base}/results/{uid}/plot.png")
                c = time.perf_counter()
                assert b"J = " in body and image[:4] == b"\x89PNG"
                html.append(b - a)
                plot.append(c - b)
                page.append(c - a)

            def ms(xs: list[float]) -> str:
                xs = sorted(xs)
                return (f"median {1e3 * statistics.median(xs):6.1f} ms, p95 {1e3 * xs[int(0.95 * (len(xs) - 1))]:6.1f} ms,"
                        f" max {1e3 * xs[-1]:6.1f} ms")

            print(f"result page, HTML + plot ({LOADS} random measurements): {ms(page)}   (goal ≤ 200 ms)")
            print(f"  HTML only: {ms(html)}")
            print(f"  plot only: {ms(plot)}")
            hist = []
            for url in (f"{base}/history", f"{base}/history?page=20&status=ok&since=2000-01-01") * 10:
                a = time.perf_counter()
                _get(url)
                hist.append(time.perf_counter() - a)
            print(f"history page (newest, and page 20 filtered; 20 loads): {ms(hist)}")
        finally:
            app.request_stop()
            main_loop.join(30)


if __name__ == "__main__":
    main()
