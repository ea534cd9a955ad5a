"""The measurement in progress: its book-keeping (``Run``), the samples it keeps, when its capture ends, the
trace made of it, and its identification job (inline or in a worker thread)."""

from __future__ import annotations

import bisect
import math
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from drivers.sensor import AngleSensor
from measurement import IdentificationResult, Trace

from .timing import SequencerConfig

if TYPE_CHECKING:
    from .states import Measurement


class Job:
    """One identification, inline or in a worker thread; the result is read once ``done`` is set.

    ``result`` is (the trace identified, its result): a sensor's ``finish`` may have replaced the trace.
    """

    def __init__(self, fn: Callable[[], tuple[Trace, IdentificationResult]]):
        self._fn = fn
        self.done = threading.Event()
        self.result: tuple[Trace, IdentificationResult] | None = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.result = self._fn()
        except BaseException as exc:  # handed to the sequencer, which turns it into FAULT with the reason
            self.error = exc
        finally:
            self.done.set()


@dataclass
class Run:
    """Book-keeping of the measurement in progress."""

    id: str
    requested_by: str
    requested_at: float
    armed_at: float
    released_at: float | None = None
    granted_pulse: float = 0.0
    capture_ended_at: float | None = None
    capture_end: str = ""
    t: list[float] = field(default_factory=list)
    angle: list[float] = field(default_factory=list)
    last_sample_at: float | None = None  # clock time a new sample last arrived
    dropped_out_of_order: int = 0
    beyond_window: int = 0  # samples later than release + capture_duration (not kept)
    outside_window: int = 0  # samples not kept: before release − pre_trigger or after release + capture_duration
    trace: Trace | None = None
    job: Job | None = None
    identify_started_at: float | None = None
    measurement: "Measurement | None" = None

    def release_time(self) -> float:
        """``released_at`` (clock time, s), for the states from RELEASING on, where it is always set."""
        assert self.released_at is not None, "the release time is read before the release"
        return self.released_at


def collect(run: Run, t: Any, angle: Any, now: float, capture_duration: float) -> None:
    """Keep the samples just read (``t`` on the sensor's clock, s; ``angle``, rad) that belong to the run."""
    t = np.asarray(t, float).ravel()
    angle = np.asarray(angle, float).ravel()
    if len(t) == 0:
        return
    finite = np.isfinite(t) & np.isfinite(angle)
    t, angle = t[finite], angle[finite]
    if run.released_at is not None:
        # the capture is bounded by sample time, not by when poll() gets round to it: a sample
        # loop that fell behind must not stretch the record (or the work) beyond the window
        inside = t <= run.released_at + capture_duration
        beyond = int(len(t) - np.count_nonzero(inside))
        run.beyond_window += beyond
        run.outside_window += beyond
        t, angle = t[inside], angle[inside]
    if len(t) == 0:
        return
    last = run.t[-1] if run.t else -math.inf
    # Trace needs strictly increasing time: a sample is kept when it is later than every one before it
    before = np.maximum.accumulate(np.concatenate(([last], t)))[:-1]
    keep = t > before
    run.dropped_out_of_order += int(len(t) - np.count_nonzero(keep))
    if keep.any():
        run.t.extend(t[keep].tolist())
        run.angle.extend(angle[keep].tolist())
        run.last_sample_at = now


def trim_pre_trigger(run: Run, pre_trigger: float) -> None:
    """Keep the last ``pre_trigger`` s before the release."""
    # the record before the release is the last pre_trigger seconds, however late the poll came that
    # released: on a fast simulated clock (or a stalled loop) the wait can be many pre-triggers long,
    # and that rest would lengthen the record and the work; the samples left out are counted
    # (the latest sample before it always stays: the rest the swing starts from, and the order guard's anchor)
    first = min(bisect.bisect_left(run.t, run.release_time() - pre_trigger), len(run.t) - 1)
    if first > 0:
        del run.t[:first], run.angle[:first]
        run.outside_window += first


def capture_end(run: Run, now: float, cfg: SequencerConfig) -> str | None:
    """Why the capture ends now (its length reached, the swing decayed), or None while it goes on."""
    released_at = run.release_time()
    elapsed = now - released_at
    if elapsed >= cfg.capture_duration or (run.t and run.t[-1] >= released_at + cfg.capture_duration) \
            or run.beyond_window:
        return f"capture complete: {cfg.capture_duration:g} s after the release"
    if cfg.decay_threshold > 0 and elapsed >= cfg.min_capture and run.t:
        t_end = run.t[-1]
        i = bisect.bisect_left(run.t, t_end - cfg.decay_window)
        if run.t[i] <= released_at and i > 0:
            return None
        window = run.angle[i:]
        if t_end - run.t[i] >= 0.9 * cfg.decay_window and len(window) >= 4:
            half_pp = 0.5 * (max(window) - min(window))
            if half_pp < cfg.decay_threshold:
                return (f"swing decayed: amplitude {half_pp:.3g} rad < {cfg.decay_threshold:g} rad "
                        f"after {elapsed:.3g} s")
    return None


def captured_trace(run: Run, sensor: AngleSensor, why: str) -> Trace:
    """The run's samples as a trace from its first sample (t0), with the sensor's statistics and flags and
    the sequencer's record of the run in its meta."""
    t = np.asarray(run.t)
    t0 = t[0]
    stats = dict(sensor.stats())
    if run.dropped_out_of_order:
        stats["dropped_out_of_order"] = run.dropped_out_of_order
    if run.outside_window:
        stats["outside_window"] = run.outside_window
    meta = {
        sensor.source: stats,
        "sequencer": {
            "measurement_id": run.id,
            "requested_by": run.requested_by,
            "t0": float(t0),  # clock time of the first sample, s: the trace's time origin
            "release_t": float(run.release_time() - t0),
            "release_pulse_s": run.granted_pulse,
            "capture_end": why,
        },
    }
    return Trace(t - t0, np.asarray(run.angle), source=sensor.source, flags=tuple(sensor.flags()), meta=meta)
