"""Bench helpers for the appliance on the simulated rig: its configuration, and its finished measurements."""

from __future__ import annotations

import threading
import time
from pathlib import Path


def simulated_doc(state_dir: Path, log_level: str = "warning") -> dict:
    """The appliance on the simulated rig (5 s swings at 100 Hz, time × 25), Modbus TCP on a free loopback port."""
    return {
        "device": {"id": "bench", "state_dir": str(state_dir), "log_level": log_level},
        "sequencer": {"pre_trigger": 0.2, "capture_duration": 5.0},
        "simulation": {"time_scale": 25.0, "rate": 100.0, "seed": 1, "sensor": "direct",
                       "effects": {"viscous": {"c": 1.5e-4}}},
        "modbus": {"host": "127.0.0.1", "port": 0},
        "web": {"enabled": False},  # its plot worker would share the CPU with what is timed
    }


class Finished:
    """Subscribed to ``app.sequencer``; ``wait(n, timeout)`` returns once n measurements have ended.

    A measurement ends in IDLE right after PUBLISHING, or in FAULT (counted in
    ``faults``, the reasons in ``fault_reasons``; leave it with the "abort" command).
    """

    def __init__(self, app) -> None:
        self.count = 0
        self.faults = 0
        self.fault_reasons: list[str] = []
        self._cond = threading.Condition()
        app.sequencer.subscribe(self._on_event)

    def _on_event(self, event) -> None:
        # spelled out, not Event.ends_measurement: the speed bench runs this against older trees too
        published = event.state.value == "IDLE" and event.previous.value == "PUBLISHING"
        fault = event.state.value == "FAULT"
        if published or fault:
            with self._cond:
                self.count += 1
                if fault:
                    self.faults += 1
                    self.fault_reasons.append(str(getattr(event, "reason", "")))
                self._cond.notify_all()

    def wait(self, n: int, timeout: float) -> bool:
        with self._cond:
            return self._cond.wait_for(lambda: self.count >= n, timeout)


class StampedIdentifier:
    """The daemon's identifier seam, timed: ``stamps[n]`` is ``time.perf_counter()`` when the n-th
    identification returned (the start of what a publisher's latency is measured from)."""

    def __init__(self, options) -> None:
        self.options = options
        self.stamps: dict[int, float] = {}

    def __call__(self, trace, rig):
        from measurement import identify

        result = identify(trace, rig, self.options)
        self.stamps[len(self.stamps) + 1] = time.perf_counter()
        return result
