"""States, the transition table and the events of the measurement sequencer."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from .sequencer import Measurement


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
