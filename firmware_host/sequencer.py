"""The measurement sequencer: IDLE → ARMED → RELEASING → CAPTURING → IDENTIFYING → PUBLISHING → IDLE.

See the package docstring (``firmware_host/__init__.py``) for the contract
the daemon relies on. Design notes (why, not what):

* Everything that changes the state happens inside ``poll()``, on the caller's
  thread. Requests from other threads (button callback, MQTT, Modbus) only
  set a flag under a lock, so subscribers always run on the polling thread
  and never race a transition.
* ``poll()`` never blocks for long: the sensor acquires in its own thread
  (or is computed on demand in simulation) and identification runs in a
  worker thread, so the daemon loop keeps pinging its watchdog.
* A sensor may finish the capture (``finish(trace) -> Trace``, optional, looked
  up with ``getattr``): the camera needs the whole swing to fit its yaw. It
  runs in the identification job, not in ``poll``, and its errors become a
  ``SensorFault`` naming the sensor; the encoder has no such hook and is
  untouched by it.
* The solenoid is switched off on every way out of RELEASING: the normal
  end of the pulse, FAULT, ABORTED, ``close()`` and an exception anywhere in
  a step; ``abort()`` and ``fault()`` switch it off at once from the calling
  thread as well, without waiting for the next poll.
"""

from __future__ import annotations

import bisect
import logging
import math
import threading
import uuid
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np

from drivers.clock import Clock
from drivers.errors import DeviceFault, SensorFault
from drivers.sensor import AngleSensor
from measurement import IdentificationResult, Options, Rig, Trace, identify
from measurement.errors import MeasurementError

from .errors import (
    CaptureTimeout,
    CaptureTooShort,
    IdentificationFailed,
    IdentificationTimeout,
    IllegalTransition,
    PublishFailed,
    SequencerConfigError,
    SequencerFault,
)
from .states import BUSY, TRANSITIONS, Event, Measurement, State

log = logging.getLogger("moi.sequencer")


# -- what the sequencer needs from its drivers ----------------------------------
class ReleaseActuator(Protocol):
    """The release solenoid as the sequencer uses it (``drivers.solenoid.Solenoid``)."""

    max_on_time: float

    def pulse(self, duration: float) -> float:
        """Energise for ``duration`` s, clamped to ``max_on_time``; returns the granted s; never blocks."""

    def off(self) -> None:
        """De-energise now (safe state)."""

    @property
    def is_active(self) -> bool: ...


class PressSource(Protocol):
    """A push button (``drivers.button.PushButton``): the sequencer sets ``when_pressed``."""

    when_pressed: Callable[[], None] | None


class StatusIndicator(Protocol):
    """An optional LED/buzzer (``drivers.indicator.Indicator``)."""

    def show(self, state: str) -> None: ...


#: the result sink: called once per successful measurement, on the polling thread, in PUBLISHING;
#: it must return quickly (queue or store; do not talk to the network here). Raising → FAULT.
ResultSink = Callable[["Measurement"], None]

#: identification seam (tests inject failures); default: measurement.identify(trace, rig, options)
Identifier = Callable[[Trace, Rig], IdentificationResult]


#: longest pre-trigger and capture, s: a record of an hour is far beyond any swing, and a longer one
#: (a typo of 1e12) would only fill the memory sample by sample
MAX_CAPTURE = 3600.0


@dataclass(frozen=True)
class SequencerConfig:
    """Timing of one measurement (angles in rad).

    The physics times (pre_trigger, release_pulse, capture_duration, decay_window,
    min_capture) are s on the sequencer's clock. The two computer time-outs
    (sample_timeout: sensor I/O; identify_timeout: processor time) are real
    seconds: on a ``ScaledClock`` the sequencer divides clock time by its
    ``scale``, so a simulation running 5× faster does not starve the bus or the fit.

    pre_trigger: capture recorded before the release (at rest at the release angle): the last
        pre_trigger seconds before it, however late the release came.
    release_pulse: how long the solenoid is asked to stay on (the solenoid clamps
        it to its own hard maximum).
    capture_duration: the capture ends this long after the release at the latest.
    decay_threshold: the capture ends earlier when the half peak-to-peak angle over
        the last ``decay_window`` falls below this (rad); 0 disables.
    min_capture: the decay test starts only this long after the release.
    sample_timeout: no new sample for this long while capturing → FAULT (capture time-out);
        real s. The release also waits for the first pre-trigger sample (never release blind).
    identify_timeout: identification longer than this → FAULT; real s.
    min_samples: fewer samples in the capture → FAULT instead of a meaningless fit.
    identify_in_worker: run identification in a worker thread (True for the daemon:
        ``poll`` stays responsive); False runs it inside ``poll`` (tests on a ManualClock).
    """

    pre_trigger: float = 0.5
    release_pulse: float = 0.15
    capture_duration: float = 30.0
    decay_threshold: float = 0.0
    decay_window: float = 2.0
    min_capture: float = 5.0
    sample_timeout: float = 1.0
    identify_timeout: float = 60.0
    min_samples: int = 50
    identify_in_worker: bool = True

    def __post_init__(self) -> None:
        def check(name: str, ok: bool, expected: str) -> None:
            if not ok:
                raise SequencerConfigError(f"sequencer: {name} = {getattr(self, name)!r}; expected {expected}")

        def finite(v: Any) -> bool:
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        check("pre_trigger", finite(self.pre_trigger) and 0 <= self.pre_trigger <= MAX_CAPTURE,
              f"a time >= 0 s and at most {MAX_CAPTURE:g} s")
        check("release_pulse", finite(self.release_pulse) and self.release_pulse > 0, "a time > 0 s")
        check("capture_duration", finite(self.capture_duration) and 0 < self.capture_duration <= MAX_CAPTURE,
              f"a time > 0 s and at most {MAX_CAPTURE:g} s")
        check("decay_threshold", finite(self.decay_threshold) and self.decay_threshold >= 0, "an angle >= 0 rad (0 disables)")
        check("decay_window", finite(self.decay_window) and self.decay_window > 0, "a time > 0 s")
        check("min_capture", finite(self.min_capture) and self.min_capture >= 0, "a time >= 0 s")
        check("sample_timeout", finite(self.sample_timeout) and self.sample_timeout > 0, "a time > 0 s")
        check("identify_timeout", finite(self.identify_timeout) and self.identify_timeout > 0, "a time > 0 s")
        check("min_samples", isinstance(self.min_samples, int) and self.min_samples >= 2, "an integer >= 2")


class _Job:
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
class _Run:
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
    job: _Job | None = None
    identify_started_at: float | None = None
    measurement: "Measurement | None" = None

    def release_time(self) -> float:
        """``released_at`` (clock time, s), for the states from RELEASING on, where it is always set."""
        assert self.released_at is not None, "the release time is read before the release"
        return self.released_at


class Sequencer:
    """The measurement state machine. See ``firmware_host`` for the contract.

    clock: the time source (``drivers.clock``): MonotonicClock on the device,
        ManualClock in tests, ScaledClock with the simulated rig.
    solenoid: the release actuator (``drivers.solenoid.Solenoid``).
    sensor: the angle sensor captured from (``drivers.sensor.AngleSensor``).
    rig: the rig identified against.
    sink: called with each finished ``Measurement`` (on the polling thread).
    config: timing (``SequencerConfig``); options: identification options.
    button: optional push button: a press is ``request_measurement("button")``.
    indicator: optional LED/buzzer: ``show(state)`` on every transition.
    identifier: replaces ``measurement.identify`` (tests).

    The sequencer does not own its drivers: ``close()`` makes them safe but
    the caller closes them.
    """

    def __init__(self, *, clock: Clock, solenoid: ReleaseActuator, sensor: AngleSensor, rig: Rig, sink: ResultSink,
                 config: SequencerConfig | None = None, options: Options | None = None,
                 button: PressSource | None = None, indicator: StatusIndicator | None = None,
                 identifier: Identifier | None = None):
        self.clock = clock
        self.solenoid = solenoid
        self.sensor = sensor
        self.rig = rig
        self.config = config or SequencerConfig()
        self.options = options or Options()
        self._sink = sink
        self._identifier = identifier or (lambda trace, rig: identify(trace, rig, self.options))
        self._button = button
        self._indicator = indicator

        self._lock = threading.Lock()        # guards the request flags and the state seen by other threads
        self._poll_lock = threading.Lock()   # one poll at a time
        self._subscribers: list[Callable[[Event], None]] = []
        self._events: list[Event] = []
        self._seq = 0

        self._state = State.IDLE
        self._since = clock.now()
        # clock seconds per real second (ScaledClock.scale): the computer time-outs are real seconds
        self._scale = float(getattr(clock, "scale", 1.0) or 1.0)
        self._run: _Run | None = None
        self._closed = False
        self._pending_request: tuple[str, float] | None = None
        self._pending_abort: str | None = None
        self._pending_fault: str | None = None
        self._pending_reset = False

        self.last_fault: str | None = None
        self.last_measurement: Measurement | None = None
        self.counts = {"measurements": 0, "faults": 0, "aborts": 0, "ignored_requests": 0}

        # the safe state from the start, whatever the solenoid was left in
        self.solenoid.off()
        if button is not None:
            button.when_pressed = self._on_button

    # -- read-only view --------------------------------------------------------
    @property
    def state(self) -> State:
        return self._state

    @property
    def busy(self) -> bool:
        """True while a measurement runs (ARMED … PUBLISHING) or one is requested."""
        with self._lock:
            return self._state in BUSY or self._pending_request is not None

    @property
    def measurement_id(self) -> str | None:
        run = self._run
        return run.id if run else None

    def status(self) -> dict[str, Any]:
        """A JSON-ready snapshot for the status topic / registers (safe from any thread)."""
        with self._lock:
            return {
                "state": self._state.value,
                "since": self._since,
                "measurement_id": self._run.id if self._run else None,
                "last_fault": self.last_fault,
                "last_measurement_id": self.last_measurement.id if self.last_measurement else None,
                "solenoid_on": bool(self.solenoid.is_active),
                **self.counts,
            }

    def progress(self, start: int = 0) -> dict[str, Any]:
        """What a live view draws (safe from any thread): the state, the run's times on the sequencer's
        clock (s), the capture length asked for, and the samples captured so far from index ``start``
        (``t`` on the sensor's clock, s; ``angle``, rad; ``next``: the index to ask from next time)."""
        run = self._run
        out: dict[str, Any] = {"state": self._state.value, "since": self._since, "now": self.clock.now(),
                               "capture_duration": self.config.capture_duration, "measurement_id": None,
                               "released_at": None, "identify_started_at": None, "t": [], "angle": [], "next": 0}
        if run is not None:
            # the lists only grow (appended on the polling thread): a slice up to a common length is consistent
            n = min(len(run.t), len(run.angle))
            start = max(0, min(int(start), n))
            out.update(measurement_id=run.id, released_at=run.released_at,
                       identify_started_at=run.identify_started_at,
                       t=run.t[start:n], angle=run.angle[start:n], next=n)
        return out

    # -- subscriptions -----------------------------------------------------------
    def subscribe(self, callback: Callable[[Event], None]) -> Callable[[], None]:
        """Call ``callback(event)`` after every transition (on the polling thread); returns an unsubscribe function.

        A callback that raises is logged and skipped; it never affects the measurement.
        """
        with self._lock:
            self._subscribers.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._subscribers:
                    self._subscribers.remove(callback)
        return unsubscribe

    # -- requests (any thread) -------------------------------------------------
    def request_measurement(self, source: str = "api") -> bool:
        """Ask for one measurement; True if accepted (it starts at the next ``poll``).

        Refused (False, logged, counted in ``counts["ignored_requests"]``) while a
        measurement runs or is already requested, in FAULT, or after ``close()``.
        """
        with self._lock:
            why = None
            if self._closed:
                why = "the sequencer is closed"
            elif self._pending_request is not None:
                why = f"a measurement requested by {self._pending_request[0]} is about to start"
            elif self._state is State.FAULT:
                why = f"in FAULT ({self.last_fault}); reset() first"
            elif self._state is not State.IDLE:
                why = f"a measurement is running ({self._state.value})"
            if why is None:
                self._pending_request = (source, self.clock.now())
                log.info("measurement requested by %s", source)
                return True
            self.counts["ignored_requests"] += 1
        log.info("measurement request from %s ignored: %s", source, why)
        return False

    def abort(self, reason: str = "aborted by request") -> bool:
        """Abandon the measurement in progress (or clear FAULT): → ABORTED → IDLE at the next ``poll``.

        The solenoid is switched off at once from this thread. False in IDLE
        (nothing to abort) unless a request was pending, which is cancelled.
        """
        with self._lock:
            if self._state is State.IDLE and self._pending_abort is None:
                if self._pending_request is None:
                    return False
                log.info("pending measurement request from %s cancelled: %s", self._pending_request[0], reason)
                self._pending_request = None
                return True
            self._pending_abort = reason
        self._solenoid_off_now()
        return True

    def fault(self, reason: str) -> bool:
        """Force FAULT with ``reason`` (e.g. the daemon found a device unhealthy); solenoid off at once.

        False if already in FAULT.
        """
        with self._lock:
            if self._state is State.FAULT:
                return False
            self._pending_fault = reason
        self._solenoid_off_now()
        return True

    def reset(self) -> bool:
        """Acknowledge a FAULT: → IDLE at the next ``poll``. False when not in FAULT."""
        with self._lock:
            if self._state is not State.FAULT:
                return False
            self._pending_reset = True
            return True

    # -- driving -----------------------------------------------------------------
    def poll(self) -> State:
        """Advance the state machine by what the clock and the devices say; returns the state.

        Non-blocking (milliseconds); call it every 10–50 ms from the main loop.
        Subscribers are called from here. Never raises for a device fault or a
        failed identification: those end in FAULT with the reason.
        """
        with self._poll_lock:
            now = self.clock.now()
            try:
                self._apply_requests(now)
                self._step(now)
            except IllegalTransition:
                self._make_safe()
                raise  # a bug in this module: do not hide it
            except Exception as exc:  # safety boundary: any device error or bug mid-measurement ends safe, in FAULT
                if isinstance(exc, (DeviceFault, SequencerFault)):
                    reason = str(exc)  # these messages name the device/step and what went wrong
                elif isinstance(exc, MeasurementError):
                    reason = f"{type(exc).__name__}: {exc}"
                else:
                    log.exception("unexpected error in state %s", self._state.value)
                    reason = f"internal error in {self._state.value}: {type(exc).__name__}: {exc}"
                self._enter_fault(now, reason)
            with self._lock:
                events, self._events = self._events, []
                subscribers = list(self._subscribers)
        for event in events:
            self._deliver(event, subscribers)
        return self._state

    def run_until_settled(self, timeout: float, poll_interval: float = 0.01) -> Event | None:
        """Poll (sleeping ``poll_interval`` s on the clock between polls) until no measurement runs.

        Returns the last event seen (PUBLISHING's IDLE, FAULT or ABORTED's IDLE),
        or None if nothing happened. After ``timeout`` s on the clock it aborts
        the measurement and returns the resulting event. For the CLI and tests;
        the daemon calls ``poll`` from its own loop instead.
        """
        seen: list[Event] = []
        unsubscribe = self.subscribe(seen.append)
        try:
            deadline = self.clock.now() + timeout
            while True:
                state = self.poll()
                if state in (State.IDLE, State.FAULT) and not self.busy:
                    return seen[-1] if seen else None
                if self.clock.now() >= deadline:
                    self.abort(f"no result within {timeout:g} s")
                    self.poll()
                    return seen[-1] if seen else None
                self._wait(poll_interval)
        finally:
            unsubscribe()

    def close(self) -> None:
        """Abort what runs, switch the solenoid off, stop the sensor, detach the button. Safe twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._pending_request = None
        if self._button is not None and getattr(self._button, "when_pressed", None) == self._on_button:
            self._button.when_pressed = None
        if self._state in BUSY:
            self.abort("sequencer closed")
            self.poll()
        self._make_safe()

    def __enter__(self) -> "Sequencer":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- internals -----------------------------------------------------------------
    def _on_button(self) -> None:
        self.request_measurement("button")

    def _wait(self, seconds: float) -> None:
        # while a worker identifies, wake up as soon as it is done rather than after a full interval
        run = self._run
        if (self._state is State.IDENTIFYING and run is not None and run.job is not None
                and not run.job.done.is_set() and run.job.done.wait(0.0)):
            return
        self.clock.sleep(seconds)

    def _transition(self, now: float, new: State, reason: str, measurement: Measurement | None = None) -> None:
        old = self._state
        if new not in TRANSITIONS[old]:
            raise IllegalTransition(f"{old.value} → {new.value} is not a legal transition ({reason})")
        with self._lock:
            self._state = new
            self._since = now
            self._seq += 1
            run = self._run
            event = Event(self._seq, now, new, old, reason, run.id if run else None, measurement)
            self._events.append(event)
        level = logging.WARNING if new in (State.FAULT, State.ABORTED) else logging.INFO
        log.log(level, "%s → %s: %s", old.value, new.value, reason)

    def _deliver(self, event: Event, subscribers: list[Callable[[Event], None]]) -> None:
        if self._indicator is not None:
            try:
                self._indicator.show(event.state.value)
            except Exception:  # a status lamp must never stop a measurement
                log.exception("indicator failed to show %s", event.state.value)
        for callback in subscribers:
            try:
                callback(event)
            except Exception:  # one broken listener must not starve the others or the machine
                log.exception("event subscriber %r failed on %s", callback, event.state.value)

    def _solenoid_off_now(self) -> None:
        try:
            self.solenoid.off()
        except Exception:  # keep going: the FAULT/abort path still runs and calls off() again
            log.exception("solenoid off() failed")

    def _make_safe(self) -> None:
        self._solenoid_off_now()
        try:
            self.sensor.stop()
        except Exception:  # a sensor that cannot stop is reported, the safe state is what matters
            log.exception("sensor stop() failed")

    def _enter_fault(self, now: float, reason: str) -> None:
        self._make_safe()
        run = self._run
        if run is not None and run.job is not None:
            run.job = None  # a late identification result is discarded
        if self._state is State.FAULT:
            log.error("further fault while in FAULT: %s", reason)
            return
        self.last_fault = reason
        self.counts["faults"] += 1
        self._transition(now, State.FAULT, reason)

    def _apply_requests(self, now: float) -> None:
        with self._lock:
            request, self._pending_request = self._pending_request, None
            abort, self._pending_abort = self._pending_abort, None
            fault, self._pending_fault = self._pending_fault, None
            reset, self._pending_reset = self._pending_reset, False
        if fault is not None and self._state is not State.FAULT:
            self._enter_fault(now, fault)
        if abort is not None and self._state is not State.IDLE:
            self._make_safe()
            self.counts["aborts"] += 1
            self._transition(now, State.ABORTED, abort)
            self._transition(now, State.IDLE, "ready after abort")
            self._run = None
            if request is not None:
                log.info("measurement request from %s dropped by the abort", request[0])
                request = None
        if reset and self._state is State.FAULT:
            self._transition(now, State.IDLE, "fault reset")
            self._run = None
        if request is not None:
            if self._state is State.IDLE:
                self._start(now, *request)
            else:  # a fault or abort raced the request
                log.info("measurement request from %s dropped: now %s", request[0], self._state.value)

    def _start(self, now: float, source: str, requested_at: float) -> None:
        # interlock: nothing may be energised when a measurement starts
        self.solenoid.off()
        self._run = _Run(id=str(uuid.uuid4()), requested_by=source, requested_at=requested_at, armed_at=now)
        self.sensor.start()
        self._transition(now, State.ARMED, f"requested by {source}; pre-trigger capture {self.config.pre_trigger:g} s")

    def _step(self, now: float) -> None:
        run = self._run
        state = self._state
        if state not in BUSY:  # IDLE, FAULT, ABORTED: nothing advances by itself
            return
        assert run is not None, f"{state.value} without a measurement in progress"
        if state in (State.ARMED, State.RELEASING, State.CAPTURING):
            self._collect(run, now)
            self._check_sample_timeout(run, now)
        if state is State.ARMED:
            if now - run.armed_at >= self.config.pre_trigger and run.t:
                if self.solenoid.is_active:  # interlock: never fire into an energised coil
                    raise DeviceFault("solenoid already energised before the release")
                run.granted_pulse = self.solenoid.pulse(self.config.release_pulse)
                run.released_at = now
                self._trim_pre_trigger(run)
                self._transition(now, State.RELEASING, f"solenoid pulse {run.granted_pulse:g} s")
        elif state is State.RELEASING:
            if now - run.release_time() >= run.granted_pulse:
                self.solenoid.off()
                self._transition(now, State.CAPTURING, "released; solenoid off, swinging freely")
        elif state is State.CAPTURING:
            end = self._capture_end(run, now)
            if end is not None:
                self._finish_capture(run, now, end)
        elif state is State.IDENTIFYING:
            self._check_identification(run, now)
        elif state is State.PUBLISHING:
            self._finish_publishing(run, now)

    def _collect(self, run: _Run, now: float) -> None:
        t, angle = self.sensor.read()  # SensorFault propagates to poll → FAULT
        t = np.asarray(t, float).ravel()
        angle = np.asarray(angle, float).ravel()
        if len(t) == 0:
            return
        finite = np.isfinite(t) & np.isfinite(angle)
        t, angle = t[finite], angle[finite]
        if run.released_at is not None:
            # the capture is bounded by sample time, not by when poll() gets round to it: a sample
            # loop that fell behind must not stretch the record (or the work) beyond the window
            inside = t <= run.released_at + self.config.capture_duration
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

    def _trim_pre_trigger(self, run: _Run) -> None:
        # the record before the release is the last pre_trigger seconds, however late the poll came that
        # released: on a fast simulated clock (or a stalled loop) the wait can be many pre-triggers long,
        # and that rest would lengthen the record and the work; the samples left out are counted
        # (the latest sample before it always stays: the rest the swing starts from, and the order guard's anchor)
        first = min(bisect.bisect_left(run.t, run.release_time() - self.config.pre_trigger), len(run.t) - 1)
        if first > 0:
            del run.t[:first], run.angle[:first]
            run.outside_window += first

    def _check_sample_timeout(self, run: _Run, now: float) -> None:
        since = run.last_sample_at if run.last_sample_at is not None else run.armed_at
        silent = (now - since) / self._scale
        if silent > self.config.sample_timeout:
            what = "since arming" if run.last_sample_at is None else "since the last one"
            raise CaptureTimeout(
                f"capture time-out: no sample from the {self.sensor.source} for {silent:.3g} s {what} "
                f"(limit {self.config.sample_timeout:g} s)")

    def _capture_end(self, run: _Run, now: float) -> str | None:
        cfg = self.config
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

    def _finish_capture(self, run: _Run, now: float, why: str) -> None:
        self._collect(run, now)
        self.sensor.stop()
        self._collect(run, now)  # what the sensor buffered up to the stop
        run.capture_ended_at = now
        run.capture_end = why
        if len(run.t) < self.config.min_samples:
            raise CaptureTooShort(
                f"capture too short: {len(run.t)} samples from the {self.sensor.source}; "
                f"expected at least {self.config.min_samples}")
        t = np.asarray(run.t)
        t0 = t[0]
        stats = dict(self.sensor.stats())
        if run.dropped_out_of_order:
            stats["dropped_out_of_order"] = run.dropped_out_of_order
        if run.outside_window:
            stats["outside_window"] = run.outside_window
        meta = {
            self.sensor.source: stats,
            "sequencer": {
                "measurement_id": run.id,
                "requested_by": run.requested_by,
                "t0": float(t0),  # clock time of the first sample, s: the trace's time origin
                "release_t": float(run.release_time() - t0),
                "release_pulse_s": run.granted_pulse,
                "capture_end": why,
            },
        }
        run.trace = Trace(t - t0, np.asarray(run.angle), source=self.sensor.source,
                          flags=tuple(self.sensor.flags()), meta=meta)
        trace, rig = run.trace, self.rig
        run.job = _Job(lambda: self._finish_and_identify(trace, rig))
        run.identify_started_at = now
        self._transition(now, State.IDENTIFYING, f"{why}; {len(trace)} samples over {trace.duration:.3g} s")
        if self.config.identify_in_worker:
            threading.Thread(target=run.job.run, name=f"moi-identify-{run.id[:8]}", daemon=True).start()
        else:
            run.job.run()

    def _finish_and_identify(self, trace: Trace, rig: Rig) -> tuple[Trace, IdentificationResult]:
        # the optional sensor hook: a camera fits its yaw over the whole swing; in the job, because
        # that takes a while and poll() must stay responsive (it counts toward identify_timeout)
        finish = getattr(self.sensor, "finish", None)
        if finish is not None:
            try:
                trace = finish(trace)
            except Exception as exc:
                raise SensorFault(f"{self.sensor.source}: finishing the capture failed: "
                                  f"{type(exc).__name__}: {exc}") from exc
            if not isinstance(trace, Trace):
                raise SensorFault(f"{self.sensor.source}: finish() returned {type(trace).__name__}; expected a Trace")
        return trace, self._identifier(trace, rig)

    def _check_identification(self, run: _Run, now: float) -> None:
        job, started_at = run.job, run.identify_started_at
        assert job is not None and started_at is not None, "IDENTIFYING without an identification started"
        if not job.done.is_set():
            busy = (now - started_at) / self._scale
            if busy > self.config.identify_timeout:
                raise IdentificationTimeout(
                    f"identification time-out: no result after {busy:.3g} s (limit {self.config.identify_timeout:g} s)")
            return
        if job.error is not None:
            exc = job.error
            if not isinstance(exc, Exception):  # KeyboardInterrupt/SystemExit in the worker: not ours to hide
                raise exc
            if isinstance(exc, SensorFault):  # from the sensor's finish(): its message names the sensor
                raise exc
            if not isinstance(exc, MeasurementError):
                log.error("identification raised", exc_info=exc)
            raise IdentificationFailed(f"identification failed: {type(exc).__name__}: {exc}") from exc
        assert job.result is not None and run.capture_ended_at is not None, "done without an error: run() stored it"
        run.trace, result = job.result
        measurement = Measurement(
            id=run.id, requested_by=run.requested_by, requested_at=run.requested_at, released_at=run.release_time(),
            capture_ended_at=run.capture_ended_at, finished_at=now, trace=run.trace, result=result,
            capture_end=run.capture_end)
        j = f"J = {result.J:.7g} kg·m²" if result.J is not None else f"omega_n = {result.omega_n:.7g} rad/s (J n/a)"
        self._transition(now, State.PUBLISHING, j, measurement)
        try:
            self._sink(measurement)
        except Exception as exc:  # the sink is the daemon's (store/outbox): its failure is a FAULT with the reason
            log.exception("result sink failed")
            raise PublishFailed(f"publishing failed: {type(exc).__name__}: {exc}") from exc
        self.last_measurement = measurement
        self.counts["measurements"] += 1
        run.measurement = measurement
        # IDLE follows at the next poll, so PUBLISHING is observable (and abortable) like every other state

    def _finish_publishing(self, run: _Run, now: float) -> None:
        measurement = run.measurement
        assert measurement is not None, "PUBLISHING without the measurement that entered it"
        self._transition(now, State.IDLE, f"published measurement {measurement.id}", measurement)
        self._run = None
