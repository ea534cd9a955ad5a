"""Clocks: the one notion of time shared by the sequencer, the drivers and the simulations.

Everything that timestamps or waits takes a ``Clock``: real hardware uses
``MonotonicClock``; tests drive a ``ManualClock`` (simulated time, never waits
on the wall clock); the simulated encoder and rig can run faster than real
time on a ``ScaledClock``. All times are seconds on that clock; only
differences are meaningful (the origin is arbitrary).
"""

from __future__ import annotations

import threading
import time
from typing import Protocol, runtime_checkable

from .errors import DriverConfigError


@runtime_checkable
class Clock(Protocol):
    """A monotonic time source, s."""

    def now(self) -> float:
        """Current time, s (monotonic, arbitrary origin)."""

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` of this clock's time pass (a manual clock just advances)."""


class MonotonicClock:
    """Real time: ``time.monotonic`` (s) and ``time.sleep``."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def __repr__(self) -> str:
        return "MonotonicClock()"


class ScaledClock:
    """Real time sped up ``scale`` times: 1 s of wall time is ``scale`` s on this clock.

    Lets a 30 s simulated swing be captured over a real transport in 30/scale
    s of wall time. Starts at 0 s when constructed.
    """

    def __init__(self, scale: float = 1.0):
        if not (isinstance(scale, (int, float)) and 0 < scale <= 1000):
            raise DriverConfigError(f"clock scale must be a number in (0, 1000], got {scale!r}")
        self.scale = float(scale)
        self._origin = time.perf_counter()

    def now(self) -> float:
        return (time.perf_counter() - self._origin) * self.scale

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds / self.scale)

    def __repr__(self) -> str:
        return f"ScaledClock(scale={self.scale:g})"


class ManualClock:
    """Simulated time that moves only when told to (``advance`` or ``sleep``); thread-safe.

    ``sleep(dt)`` advances the time by ``dt`` instead of waiting, so a
    sequencer loop written against ``Clock`` runs at full speed in tests.
    """

    def __init__(self, start: float = 0.0):
        self._t = float(start)
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._t

    def advance(self, seconds: float) -> float:
        """Move the time forward by ``seconds`` (>= 0); returns the new time, s."""
        if not seconds >= 0:
            raise ValueError(f"a clock only moves forward; got advance({seconds!r})")
        with self._lock:
            self._t += float(seconds)
            return self._t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.advance(seconds)

    def __repr__(self) -> str:
        return f"ManualClock(t={self.now():g})"
