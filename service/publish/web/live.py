"""The live state a page shows: one JSON message per sequencer transition, and a tick with the progress."""

from __future__ import annotations

import time
import uuid
from typing import TYPE_CHECKING, Any

from ..words import STATE_WORDS

if TYPE_CHECKING:  # pragma: no cover
    from firmware_host import Event
    from service.publish.port import ApplianceView

#: at most this many samples in one tick (a page that opens late catches up over a few ticks)
MAX_SAMPLES_PER_TICK = 4000


def extras(app: "ApplianceView") -> dict[str, Any]:
    """The active recipe (name, number) and part ID, where the appliance has them."""
    parts = getattr(app, "parts", None)
    if parts is None:
        return {}
    r = parts.recipe
    out: dict[str, Any] = {"recipe": {"name": r.name, "number": r.number} if r is not None else None,
                           "part_id": parts.part_id, "release_next": None}
    if r is not None and r.spec is not None:
        o = parts.open_part
        # the release a trigger now measures (during a capture: the one being measured), of the part's N; an
        # open part of another part ID or recipe is abandoned by the next release, which starts a new part
        same = o is not None and o["part_id"] == parts.part_id and o["recipe"] == r.name
        out["release_next"] = {"k": (o["done"] + 1) if same else 1, "of": r.releases}
    return out


class Live:
    """Every message carries ``boot``: a page that sees it change knows the daemon restarted under it (its part in
    hand, its session and its verdict are gone), and ``measure_refused``: a calibration block reaches an open page
    as it starts."""

    def __init__(self, app: "ApplianceView") -> None:
        self.app = app
        # the daemon's life, not the wall clock: two starts within one second still differ
        self.boot = uuid.uuid4().hex[:12]
        self.started = time.time()

    def event_message(self, event: "Event") -> dict[str, Any]:
        d = self.app.public_event(event)  # a result's values only once it is stored
        d["type"] = "state"
        d["words"] = STATE_WORDS.get(d["state"], "")
        d["wall"] = time.time()
        d["boot"] = self.boot
        return d

    def snapshot(self, cursor: dict[str, Any] | None = None) -> dict[str, Any]:
        """The state now, the capture/identification progress and (with a cursor: the page's
        {"measurement_id", "next"}) the samples the page has not drawn yet."""
        app = self.app
        seq = app.sequencer
        live = app.live_status()
        out: dict[str, Any] = {"type": "tick", "state": live.state, "words": STATE_WORDS.get(live.state or "", ""),
                               "fault": None, "measurement_id": None, "boot": self.boot,
                               "measure_refused": live.measure_refused, **extras(app)}
        if seq is None:
            return out
        status = seq.status()
        if live.state == "FAULT":
            out["fault"] = status.get("last_fault")
        start = 0
        if cursor is not None and cursor.get("measurement_id") == seq.measurement_id:
            start = int(cursor.get("next") or 0)
        p = seq.progress(start)
        cfg = seq.config
        out.update(measurement_id=p["measurement_id"], last_measurement_id=status.get("last_measurement_id"),
                   capture_duration=p["capture_duration"], pre_trigger=cfg.pre_trigger)
        now = p["now"]
        if p["released_at"] is not None and live.state in ("CAPTURING", "RELEASING"):
            elapsed = now - p["released_at"]
            out["elapsed"] = elapsed
            out["remaining"] = max(0.0, p["capture_duration"] - elapsed)
        if p["identify_started_at"] is not None and live.state == "IDENTIFYING":
            scale = float(getattr(seq.clock, "scale", 1.0) or 1.0)
            out["identifying_for"] = (now - p["identify_started_at"]) / scale  # real seconds
            last = seq.last_measurement
            if last is not None:
                out["identify_typical"] = (last.finished_at - last.capture_ended_at) / scale
        if cursor is not None:
            t, a = p["t"][:MAX_SAMPLES_PER_TICK], p["angle"][:MAX_SAMPLES_PER_TICK]
            if t and p["measurement_id"] is not None:
                # times relative to the first sample of the run: the page draws from 0
                origin = cursor.get("origin")
                if cursor.get("measurement_id") != p["measurement_id"] or origin is None:
                    origin = t[0]
                out["samples"] = {"t": [round(x - origin, 4) for x in t], "angle": [round(x, 6) for x in a]}
                cursor.update(measurement_id=p["measurement_id"], next=start + len(t), origin=origin)
                out["reset"] = start == 0
        return out
