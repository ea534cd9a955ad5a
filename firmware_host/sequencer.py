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

import logging
import threading
import uuid
from typing import Any, Callable

from drivers.clock import Clock
from drivers.errors import DeviceFault, SensorFault
from drivers.sensor import AngleSensor
from measurement import IdentificationResult, Options, Rig, Trace, identify
from measurement.errors import MeasurementError

from .capture import Job, Run, capture_end, captured_trace, collect, trim_pre_trigger
from .errors import (
    CaptureTimeout,
    CaptureTooShort,
    IdentificationFailed,
    IdentificationTimeout,
    IllegalTransition,
    PublishFailed,
    SequencerFault,
    fault_words,
)
from .ports import Identifier, PressSource, ReleaseActuator, ResultSink, StatusIndicator
from .states import BUSY, TRANSITIONS, Event, Measurement, State
from .timing import SequencerConfig

log = logging.getLogger("moi.sequencer")



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
        self._run: Run | None = None
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
                    reason = fault_words(exc)
                else:
                    log.exception("unexpected error in state %s", self._state.value)
                    reason = f"internal error in {self._state.value}: {fault_words(exc)}"
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
        self._run = Run(id=str(uuid.uuid4()), requested_by=source, requested_at=requested_at, armed_at=now)
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
                trim_pre_trigger(run, self.config.pre_trigger)
                self._transition(now, State.RELEASING, f"solenoid pulse {run.granted_pulse:g} s")
        elif state is State.RELEASING:
            if now - run.release_time() >= run.granted_pulse:
                self.solenoid.off()
                self._transition(now, State.CAPTURING, "released; solenoid off, swinging freely")
        elif state is State.CAPTURING:
            end = capture_end(run, now, self.config)
            if end is not None:
                self._finish_capture(run, now, end)
        elif state is State.IDENTIFYING:
            self._check_identification(run, now)
        elif state is State.PUBLISHING:
            self._finish_publishing(run, now)

    def _collect(self, run: Run, now: float) -> None:
        t, angle = self.sensor.read()  # SensorFault propagates to poll → FAULT
        collect(run, t, angle, now, self.config.capture_duration)

    def _check_sample_timeout(self, run: Run, now: float) -> None:
        since = run.last_sample_at if run.last_sample_at is not None else run.armed_at
        silent = (now - since) / self._scale
        if silent > self.config.sample_timeout:
            what = "since arming" if run.last_sample_at is None else "since the last one"
            raise CaptureTimeout(
                f"capture time-out: no sample from the {self.sensor.source} for {silent:.3g} s {what} "
                f"(limit {self.config.sample_timeout:g} s)")

    def _finish_capture(self, run: Run, now: float, why: str) -> None:
        self._collect(run, now)
        self.sensor.stop()
        self._collect(run, now)  # what the sensor buffered up to the stop
        run.capture_ended_at = now
        run.capture_end = why
        if len(run.t) < self.config.min_samples:
            raise CaptureTooShort(
                f"capture too short: {len(run.t)} samples from the {self.sensor.source}; "
                f"expected at least {self.config.min_samples}")
        run.trace = captured_trace(run, self.sensor, why)
        trace, rig = run.trace, self.rig
        run.job = Job(lambda: self._finish_and_identify(trace, rig))
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
                raise SensorFault(f"{self.sensor.source}: finishing the capture failed: {fault_words(exc)}") from exc
            if not isinstance(trace, Trace):
                raise SensorFault(f"{self.sensor.source}: finish() returned {type(trace).__name__}; expected a Trace")
        return trace, self._identifier(trace, rig)

    def _check_identification(self, run: Run, now: float) -> None:
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
            raise IdentificationFailed(f"identification failed: {fault_words(exc)}") from exc
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
            raise PublishFailed(f"publishing failed: {fault_words(exc)}") from exc
        self.last_measurement = measurement
        self.counts["measurements"] += 1
        run.measurement = measurement
        # IDLE follows at the next poll, so PUBLISHING is observable (and abortable) like every other state

    def _finish_publishing(self, run: Run, now: float) -> None:
        measurement = run.measurement
        assert measurement is not None, "PUBLISHING without the measurement that entered it"
        self._transition(now, State.IDLE, f"published measurement {measurement.id}", measurement)
        self._run = None
