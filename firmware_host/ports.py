"""What the sequencer needs from its drivers and its caller: the release actuator, the button, the status
lamp (structural types the drivers meet), the result sink and the identification seam."""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol

from measurement import IdentificationResult, Rig, Trace

if TYPE_CHECKING:
    from .states import Measurement


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
