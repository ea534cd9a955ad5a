"""The measurement sequencer: arm → release → capture → identify → publish, with interlocks.

Contract (what the daemon in ``service/`` builds on; kept stable)
------------------------------------------------------------------

States (``State``, a ``str`` enum; the value is the published name)::

    IDLE → ARMED → RELEASING → CAPTURING → IDENTIFYING → PUBLISHING → IDLE
    FAULT    from every state (latched: leave it with reset() or abort())
    ABORTED  from every state but IDLE (transient: always followed by IDLE)

    ARMED        capture started (pre-trigger), solenoid off; waits pre_trigger s
                 and at least one sample (never releases blind)
    RELEASING    solenoid pulse (clamped by the solenoid's hard maximum on-time)
    CAPTURING    solenoid off, free swing; ends after capture_duration s or when
                 the swing decayed below decay_threshold rad
    IDENTIFYING  identification in a worker thread (poll() stays responsive)
    PUBLISHING   the result sink is called once with the ``Measurement`` on entry;
                 IDLE follows at the next poll (an abort in PUBLISHING does not
                 recall a result the sink already has)

Construction (everything injected; the sequencer owns none of its drivers)::

    seq = Sequencer(clock=MonotonicClock(), solenoid=Solenoid(...), sensor=ModbusEncoder(...),
                    rig=rig, sink=on_measurement, config=SequencerConfig(...),
                    options=measurement.Options(), button=PushButton(...) | None,
                    indicator=Indicator(...) | None)

Driving: the daemon's main loop calls ``seq.poll()`` every 10–50 ms. ``poll``
is non-blocking (milliseconds: the encoder samples in its own thread, the
identification in a worker), so the loop keeps pinging the systemd watchdog
during a measurement. All transitions, and therefore all subscriber callbacks
and the sink call, happen inside ``poll`` on the polling thread. The CLI and
tests may use ``seq.run_until_settled(timeout)`` instead.

Requests (thread-safe, from any thread: button callback, MQTT, Modbus coil):

    seq.request_measurement(source: str = "api") -> bool
        True if accepted (starts at the next poll); False, logged and counted in
        ``seq.counts["ignored_requests"]`` while busy, already requested or in FAULT.
        A configured button calls request_measurement("button").
    seq.abort(reason: str = "aborted by request") -> bool
        Solenoid off at once; ABORTED → IDLE at the next poll. False in IDLE.
    seq.fault(reason: str) -> bool      force FAULT (solenoid off at once)
    seq.reset() -> bool                 FAULT → IDLE at the next poll
    seq.close()                         abort, solenoid off, sensor stopped; safe twice

Observing::

    seq.subscribe(callback: Callable[[Event], None]) -> unsubscribe: Callable[[], None]
        Called after every transition with ``Event(seq, time, state, previous,
        reason, measurement_id, measurement)``; ``event.to_dict()`` is JSON-ready.
        ``measurement`` is set on the PUBLISHING event and the IDLE after it.
        A raising callback is logged and skipped.
    seq.state -> State;  seq.busy -> bool;  seq.status() -> dict (JSON-ready snapshot);
    seq.last_fault -> str | None;  seq.last_measurement -> Measurement | None;  seq.counts -> dict

Result sink: ``sink(measurement: Measurement) -> None``, called once per
successful measurement inside ``poll`` during PUBLISHING. It must return
quickly (store in the outbox, do not wait on the network); if it raises, the
sequencer goes to FAULT ("publishing failed: ..."). ``Measurement`` carries
``id`` (UUID4), ``requested_by``, clock times, the ``trace`` and the
``result`` (``measurement.IdentificationResult``); ``measurement.to_dict()`` is
the result's JSON plus ``id``, ``requested_by`` and ``timing``. Encoder error
counts are in ``result.acquisition["encoder"]`` and the flag
``encoder_errors`` in ``result.flags``; the camera's frame counts, yaw and
edge figures in ``result.acquisition["camera"]`` and its flags
``marker_lost``, ``corrupt_frame``, ``dropped_frames``, ``camera_pose``.

Sensor (``drivers.sensor.AngleSensor``): ``ModbusEncoder``, ``CameraAngleSensor``
(``drivers.camera_sensor``) or ``SimulatedAngleSensor``. Optional hook: a sensor
that has ``finish(trace: Trace) -> Trace`` gets the captured trace once per
measurement, after ``stop()`` and before identification, in the identification
job (worker thread or inline; it counts toward ``identify_timeout``). The trace
it returns is the one identified, put in the ``Measurement`` and published. The
camera fits its yaw over the whole swing there and corrects the angles
(``acquisition.camera.yaw_deg``, flag ``camera_pose``). If it raises, FAULT
with "<source>: finishing the capture failed: ...". Sensors without it (the
encoder) are unaffected.

Faults never raise out of ``poll``: sensor faults (``drivers.errors.SensorFault``:
``EncoderFault``; the camera's run of frames without the marker, or a camera
that stops delivering), capture time-out, too short a capture, identification errors or time-out,
sink errors and unexpected exceptions all end in FAULT with the reason in the
event, ``seq.last_fault`` and ``status()``; the solenoid is off on every exit
path. Only ``IllegalTransition`` (a bug here) propagates.

Clocks (``drivers.clock``, re-exported here): ``MonotonicClock`` on the device,
``ManualClock`` in tests (``sleep`` advances it: no wall-clock waits), and
``ScaledClock`` for the simulated rig running faster than real time. Physics
times of ``SequencerConfig`` are clock seconds; its two computer time-outs
(``sample_timeout``, ``identify_timeout``) are real seconds (clock time divided
by ``clock.scale`` when the clock has one).
"""

from drivers.clock import Clock, ManualClock, MonotonicClock, ScaledClock

from .errors import (
                     CaptureTimeout,
                     CaptureTooShort,
                     IdentificationFailed,
                     IdentificationTimeout,
                     IllegalTransition,
                     PublishFailed,
                     SequencerConfigError,
                     SequencerError,
                     SequencerFault,
)
from .ports import Identifier, ResultSink
from .sequencer import Sequencer
from .states import BUSY, TRANSITIONS, Event, Measurement, State
from .timing import SequencerConfig

__all__ = [
    "Clock", "ManualClock", "MonotonicClock", "ScaledClock",
    "Sequencer", "SequencerConfig", "Measurement", "ResultSink", "Identifier",
    "State", "Event", "TRANSITIONS", "BUSY",
    "SequencerError", "SequencerConfigError", "SequencerFault", "IllegalTransition", "CaptureTimeout",
    "CaptureTooShort", "IdentificationTimeout", "IdentificationFailed", "PublishFailed",
]
