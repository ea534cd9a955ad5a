"""Bench: the largest simulated time scale (×1000) end to end in the daemon.

N measurements of 20 s swings (0.2 s pre-trigger) at time × 1000 on the simulated rig, web page on (its
plot queue is what grew before). Reports each record's span against pre-trigger + window, the
measurements that ended in FAULT, and the daemon's resident memory before and after.

Run: `.venv/bin/python bench/bench_time_scale.py` (or `make bench`). Numbers are printed, never asserted.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import threading
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(1, str(HERE))
os.environ.setdefault("GPIOZERO_PIN_FACTORY", "mock")

from bench_speed import _status_kb  # noqa: E402  (the benches' reading of /proc/self/status)

N = 40
PRE, WINDOW = 0.2, 20.0


def _rss_mb() -> float:
    return _status_kb("VmRSS") / 1024


def main() -> None:
    from _appliance import Finished, simulated_doc

    from service.config.appliance import parse_config
    from service.daemon import Appliance

    with tempfile.TemporaryDirectory() as tmp:
        doc = simulated_doc(Path(tmp) / "state")
        doc["sequencer"] = {"pre_trigger": PRE, "capture_duration": WINDOW}
        doc["simulation"]["time_scale"] = 1000.0
        doc["web"] = {"enabled": True, "port": 0}
        app = Appliance(parse_config(doc, source="bench"), poll_interval=0.02)
        app.start()
        assert app.sequencer is not None and app.store is not None
        sequencer, store = app.sequencer, app.store
        loop = threading.Thread(target=app.run, daemon=True)
        loop.start()
        finished = Finished(app)
        rss0 = _rss_mb()
        for i in range(1, N + 1):
            app.command("trigger", "bench")
            if not finished.wait(i, 120):
                print(f"measurement {i} did not end in 120 s")
                break
            if finished.faults and sequencer.state.value == "FAULT":
                app.command("abort", "bench")
        rss1 = _rss_mb()
        spans, releases = [], []
        for m in store.list(limit=None):
            if m.status != "ok":
                continue
            s = store.get(m.uuid, trace=True)
            spans.append(s.trace_t[-1] - s.trace_t[0])
            releases.append(s.trace_meta["sequencer"]["release_t"])
        app.request_stop()
        loop.join(60)
    print(f"{N} measurements at time × 1000, {PRE:g} s pre-trigger + {WINDOW:g} s window: "
          f"{finished.faults} FAULT ({', '.join(sorted(set(finished.fault_reasons))) or 'none'})")
    if spans:
        print(f"  record span: median {statistics.median(spans):.3f} s, {min(spans):.3f}–{max(spans):.3f} s "
              f"(expected {PRE + WINDOW:g} s); release at {min(releases):.3f}–{max(releases):.3f} s")
    print(f"  resident memory: {rss0:.0f} MB after start-up, {rss1:.0f} MB after {N} measurements")


if __name__ == "__main__":
    main()
