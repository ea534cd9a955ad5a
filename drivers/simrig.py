"""The simulated rig: a pendulum held at its release angle until the mock solenoid fires.

It couples the mocks to the physics. The rig listens to the solenoid (any
``drivers.solenoid.Solenoid``, normally on gpiozero's mock pins): the first
energising after ``relatch()`` releases the pendulum, which then swings
according to ``measurement.Pendulum`` (any effects of the library). Readers
ask for the true angle at a time on the shared clock through ``angle(t)``,
the ``AngleSource`` that the simulated encoder server, the in-process
``SimulatedAngleSensor`` and the mock camera all take.

A real operator swings the pendulum back and latches it between
measurements; ``relatch()`` is that operator.
"""

from __future__ import annotations

import math
import threading
from typing import Any, Callable

import numpy as np

from measurement import Pendulum, Swing

from .clock import Clock
from .errors import DriverConfigError

#: longest simulated swing, s (θ holds its last value afterwards)
MAX_DURATION = 3600.0


class SimRig:
    """A pendulum on a rig, released by a solenoid, readable as θ(t) on the shared clock.

    pendulum: the truth (rig, J, effects with values).
    theta0: release angle, rad (held there until released).
    clock: the clock every reader uses (ManualClock, ScaledClock, MonotonicClock).
    duration: how long after the release the swing is simulated, s (θ is held at
        its last value afterwards); pick at least the capture duration.
    """

    def __init__(self, pendulum: Pendulum, *, theta0: float, clock: Clock, duration: float = 60.0):
        if not (isinstance(theta0, (int, float)) and math.isfinite(theta0) and 0 < abs(theta0) < math.pi):
            raise DriverConfigError(f"simulated rig: theta0 must be a release angle 0 < |θ0| < π rad, got {theta0!r}")
        if not (isinstance(duration, (int, float)) and 0 < duration <= MAX_DURATION):
            raise DriverConfigError(f"simulated rig: duration must be in (0, {MAX_DURATION:g}] s, got {duration!r}")
        self.pendulum = pendulum
        self.theta0 = float(theta0)
        self.clock = clock
        self.swing = Swing(pendulum, theta0=self.theta0, duration=float(duration))
        self._lock = threading.Lock()
        self._released_at: float | None = None
        self._detach: list[Callable[[], None]] = []
        self.releases = 0

    # -- truth ------------------------------------------------------------------------
    @property
    def inertia(self) -> float:
        """True J about the pivot, kg·m²."""
        return self.pendulum.inertia

    @property
    def released_at(self) -> float | None:
        """Clock time of the release (s), None while latched."""
        return self._released_at

    def truth(self) -> dict[str, Any]:
        """What a test compares against: J, ω_n, effects, θ0."""
        return {"J": self.pendulum.inertia, "omega_n": self.pendulum.omega_n, "theta0": self.theta0,
                "effects": {k: dict(v) for k, v in self.pendulum.effects.items()}}

    def angle(self, t: float) -> float:
        """True angle (rad) at time ``t`` (s) on the rig's clock: θ0 while latched, the free swing after."""
        released = self._released_at
        if released is None or t <= released:
            return self.theta0
        return float(self.swing.angle(t - released))

    def angles(self, t: np.ndarray) -> np.ndarray:
        """``angle`` at many times at once (rad): a fast simulated clock asks for thousands per read."""
        t = np.asarray(t, dtype=float)
        released = self._released_at
        if released is None:
            return np.full(t.shape, self.theta0)
        return np.asarray(self.swing.angle(t - released), dtype=float).reshape(t.shape)

    # -- coupling ---------------------------------------------------------------------
    def attach(self, solenoid: Any) -> "SimRig":
        """Release the pendulum when ``solenoid`` energises (uses ``solenoid.add_listener``)."""
        self._detach.append(solenoid.add_listener(self._on_solenoid))
        return self

    def release(self) -> None:
        """Release now (as the solenoid does); ignored when already released."""
        with self._lock:
            if self._released_at is None:
                self._released_at = self.clock.now()
                self.releases += 1

    def mount(self, pendulum: Pendulum) -> None:
        """Put another part (or the same part in another orientation) on the rig: what the operator does
        between two steps of a tensor set. Only while latched: a swinging pendulum keeps its part."""
        swing = Swing(pendulum, theta0=self.theta0, duration=self.swing.duration)
        with self._lock:
            if self._released_at is not None:
                self._released_at = None  # the operator stops the swing to remount the part
            self.pendulum = pendulum
            self.swing = swing

    def relatch(self) -> None:
        """Swing the pendulum back to θ0 and latch it (the operator between measurements)."""
        with self._lock:
            self._released_at = None

    def close(self) -> None:
        """Detach from the solenoid(s); safe twice."""
        while self._detach:
            self._detach.pop()()

    def __enter__(self) -> "SimRig":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _on_solenoid(self, active: bool) -> None:
        if active:
            self.release()
