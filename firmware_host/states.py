"""States, the transition table and the events of the measurement sequencer."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from measurement import IdentificationResult, Trace


class State(str, enum.Enum):
    """Sequencer states; the value is the name published to the outside."""

    IDLE = "IDLE"                # safe, waiting for a request
    ARMED = "ARMED"              # capture running (pre-trigger), solenoid still off
    RELEASING = "RELEASING"      # solenoid pulse in progress, capture running
    CAPTURING = "CAPTURING"      # pendulum swinging freely, capture running
    IDENTIFYING = "IDENTIFYING"  # capture over, fitting the trace
    PUBLISHING = "PUBLISHING"    # handing the result to the sink
    FAULT = "FAULT"              # latched until reset() or abort(); solenoid off
    ABORTED = "ABORTED"          # transient: a measurement was abandoned; goes to IDLE

    def __str__(self) -> str:
        return self.value


#: while in one of these a measurement is running (requests are refused)
BUSY = frozenset({State.ARMED, State.RELEASING, State.CAPTURING, State.IDENTIFYING, State.PUBLISHING})

#: every legal transition; anything else raises IllegalTransition
TRANSITIONS: dict[State, frozenset[State]] = {
    State.IDLE: frozenset({State.ARMED, State.FAULT}),
    State.ARMED: frozenset({State.RELEASING, State.FAULT, State.ABORTED}),
    State.RELEASING: frozenset({State.CAPTURING, State.FAULT, State.ABORTED}),
    State.CAPTURING: frozenset({State.IDENTIFYING, State.FAULT, State.ABORTED}),
    State.IDENTIFYING: frozenset({State.PUBLISHING, State.FAULT, State.ABORTED}),
    State.PUBLISHING: frozenset({State.IDLE, State.FAULT, State.ABORTED}),
    State.FAULT: frozenset({State.IDLE, State.ABORTED}),
    State.ABORTED: frozenset({State.IDLE}),
}


@dataclass(frozen=True, eq=False)
class Measurement:
    """One finished measurement, handed to the result sink.

    id: UUID4 string; requested_by: who asked ("button", "mqtt", "modbus", "cli", ...).
    requested_at / released_at / capture_ended_at / finished_at: s on the sequencer's clock.
    trace: the captured trace (t from the first pre-trigger sample, s; angle, rad).
    result: the identification result (J, damping, flags, acquisition counts...).
    capture_end: why the capture ended, in words.
    """

    id: str
    requested_by: str
    requested_at: float
    released_at: float
    capture_ended_at: float
    finished_at: float
    trace: Trace
    result: IdentificationResult
    capture_end: str

    def to_dict(self) -> dict[str, Any]:
        """The result's JSON (``IdentificationResult.to_dict()``) plus ``id``, ``requested_by`` and ``timing``."""
        d: dict[str, Any] = {"id": self.id, "requested_by": self.requested_by}
        d.update(self.result.to_dict())
        d["timing"] = {
            "released_after_request_s": self.released_at - self.requested_at,
            "capture_s": self.capture_ended_at - self.released_at,
            "capture_to_result_s": self.finished_at - self.capture_ended_at,
            "capture_end": self.capture_end,
            "samples": len(self.trace),
        }
        return d


@dataclass(frozen=True, eq=False)
class Event:
    """One state transition, as delivered to subscribers.

    seq: 1, 2, ... per sequencer (gaps never happen; lets a listener spot loss).
    time: s on the sequencer's clock.
    state / previous: the new and the old state.
    reason: why, in words ("requested by button", "encoder fault: ...").
    measurement_id: UUID of the measurement this transition belongs to (None in IDLE without one).
    measurement: the finished ``Measurement`` on the PUBLISHING event (and the IDLE after it), else None.
    """

    seq: int
    time: float
    state: State
    previous: State
    reason: str
    measurement_id: str | None = None
    measurement: "Measurement | None" = None

    @property
    def ends_measurement(self) -> bool:
        """The measurement in progress is over: back in IDLE from its last step, or in FAULT."""
        return self.state in (State.IDLE, State.FAULT) and self.previous is not State.IDLE

    @property
    def publishes(self) -> bool:
        """The finished measurement is handed over to be stored and published (``measurement`` is set)."""
        return self.state is State.PUBLISHING and self.measurement is not None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the full result is in ``measurement.to_dict()``)."""
        d: dict[str, Any] = {
            "seq": self.seq, "time": self.time, "state": self.state.value, "previous": self.previous.value,
            "reason": self.reason, "measurement_id": self.measurement_id,
        }
        if self.measurement is not None:
            r = self.measurement.result
            d["J"] = r.J
            d["J_std"] = r.J_std
            d["omega_n"] = r.omega_n
        return d
