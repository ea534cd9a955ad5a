"""The angle-sensor seam between the sequencer and whatever records the swing.

``AngleSensor`` is what the sequencer captures from: the Modbus encoder
(``drivers.encoder.ModbusEncoder``), the camera
(``drivers.camera_sensor.CameraAngleSensor``), or the in-process
``SimulatedAngleSensor`` below (deterministic in simulated time, for the
sequencer's state-machine tests).

Optional beyond the protocol: ``finish(trace) -> Trace``, called once by the
sequencer on the whole capture before identification (the camera fits its
yaw there; see ``firmware_host``).

Timestamps are seconds on the sensor's injected ``Clock`` (the same clock the
sequencer runs on); angles are radians, positive in the rig's positive
direction, zero wherever the sensor's zero is (the identification fits the
offset).
"""

from __future__ import annotations

import math
import threading
from typing import Callable, Protocol, runtime_checkable

import numpy as np

from .clock import Clock
from .errors import DriverConfigError, SensorFault

#: time on the injected clock (s) → true angle (rad); what the simulated rig exposes
AngleSource = Callable[[float], float]


@runtime_checkable
class AngleSensor(Protocol):
    """A source of timestamped angle samples for one capture at a time.

    source: short name copied into ``Trace.source`` and the key of ``stats()``
    in ``Trace.meta`` ("encoder", "camera").
    """

    source: str

    def start(self) -> None:
        """Begin acquiring; samples from before this call are never returned."""

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """Samples acquired since the previous ``read`` (or ``start``): (t in s on the clock, angle in rad).

        Never blocks for long (returns what is there, possibly nothing).
        Raises ``SensorFault`` (e.g. ``EncoderFault``) once acquisition failed.
        """

    def stop(self) -> None:
        """Stop acquiring (safe to call when not started, and twice)."""

    def stats(self) -> dict:
        """Counters of the current/last capture (samples, errors...), JSON-ready."""

    def flags(self) -> tuple[str, ...]:
        """Quality flags of the last capture for ``Trace.flags`` (e.g. "encoder_errors")."""

    def close(self) -> None:
        """Release the device (safe twice)."""


class SampleBuffer:
    """The samples of one capture, taken on an acquisition thread and drained by ``read()`` on another.

    ``add`` appends a sample (t in s, angle in rad) and wakes waiters; ``fail`` records the first
    fault of the capture (``drain`` raises it from then on); ``drain`` returns and forgets the
    samples since the previous drain; ``wait_for(n, timeout)`` blocks until ``n`` samples were
    taken since ``reset`` or a fault. ``lock`` (re-entrant) also guards the owner's counters.
    """

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self._arrived = threading.Condition(self.lock)  # notified on every sample and on a fault
        self.reset()

    def reset(self) -> None:
        """Empty, no fault: a new capture."""
        with self.lock:
            self._t: list[float] = []
            self._a: list[float] = []
            self.count = 0              # samples taken since reset
            self.first_t = 0.0          # s, time of the first and the last of them
            self.last_t = -math.inf
            self.fault: SensorFault | None = None

    def add(self, t: float, angle: float) -> None:
        with self.lock:
            self._t.append(float(t))
            self._a.append(float(angle))
            if self.count == 0:
                self.first_t = float(t)
            self.last_t = float(t)
            self.count += 1
            self._arrived.notify_all()

    def fail(self, fault: SensorFault) -> bool:
        """Record ``fault`` unless the capture already has one; True when it is the first."""
        with self.lock:
            first = self.fault is None
            if first:
                self.fault = fault
            self._arrived.notify_all()
            return first

    def drain(self) -> tuple[np.ndarray, np.ndarray]:
        """The samples since the last drain: (t in s, angle in rad); raises the capture's fault, if any."""
        with self.lock:
            if self.fault is not None:
                raise self.fault
            t, a = self._t, self._a
            self._t, self._a = [], []
        return np.asarray(t, dtype=float), np.asarray(a, dtype=float)

    def wait_for(self, n: int, timeout: float) -> bool:
        """Block until ``n`` samples were taken (True), a fault, or ``timeout`` s of real time (False)."""
        with self._arrived:
            return self._arrived.wait_for(lambda: self.count >= n or self.fault is not None, timeout) \
                and self.fault is None

    def rate(self) -> float | None:
        """Mean sample rate of the capture so far, Hz (None with fewer than 2 samples)."""
        with self.lock:
            if self.count > 1 and self.last_t > self.first_t:
                return (self.count - 1) / (self.last_t - self.first_t)
        return None


class SimulatedAngleSensor:
    """An in-process sensor sampling an angle source at a fixed rate on the injected clock.

    Every ``read`` returns the samples whose nominal times (``start`` + k/rate)
    have passed on the clock, so with a ``ManualClock`` a capture is exactly
    reproducible and costs no wall time. Faults for tests: ``inject_fault``
    makes the next ``read`` raise, ``stall`` stops new samples (a silent
    sensor, for the capture time-out).

    rate: Hz; noise_std: rad; quantisation_bits: encoder resolution (2π/2^bits).
    """

    def __init__(self, angle_source: AngleSource, clock: Clock, *, rate: float = 200.0, noise_std: float = 0.0,
                 quantisation_bits: int | None = None, seed: int | None = None, source: str = "encoder"):
        if not (rate > 0 and math.isfinite(rate)):
            raise DriverConfigError(f"sample rate must be > 0 Hz, got {rate!r}")
        if not noise_std >= 0:
            raise DriverConfigError(f"noise_std must be >= 0 rad, got {noise_std!r}")
        self.source = source
        self._angle = angle_source
        self._clock = clock
        self._rate = float(rate)
        self._noise = float(noise_std)
        self._bits = quantisation_bits
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._t0: float | None = None
        self._next = 0
        self._fault: str | None = None
        self._stalled = False
        self._count = 0

    def start(self) -> None:
        with self._lock:
            self._t0 = self._clock.now()
            self._next = 0
            self._count = 0
            self._fault = None
            self._stalled = False

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        with self._lock:
            if self._fault is not None:
                raise SensorFault(self._fault)
            if self._t0 is None or self._stalled:
                return np.empty(0), np.empty(0)
            last = int(math.floor((self._clock.now() - self._t0) * self._rate))
            k = np.arange(self._next, last + 1)
            self._next = last + 1
        t = self._t0 + k / self._rate
        # a source with a vectorised form (SimRig.angles) is asked once per read: at a fast simulated
        # clock one read covers thousands of samples, and a per-sample loop made the poll fall behind
        many = getattr(getattr(self._angle, "__self__", None), "angles", None)
        if many is not None and getattr(self._angle, "__name__", "") == "angle":
            angle = np.asarray(many(t), dtype=float)
        else:
            angle = np.array([self._angle(float(x)) for x in t], dtype=float)
        if self._noise:
            angle = angle + self._rng.normal(0.0, self._noise, angle.size)
        if self._bits:
            step = 2.0 * math.pi / (1 << self._bits)
            angle = np.round(angle / step) * step
        self._count += int(k.size)
        return t, angle

    def stop(self) -> None:
        with self._lock:
            self._t0 = None

    def stats(self) -> dict:
        return {"samples": self._count, "rate_hz": self._rate}

    def flags(self) -> tuple[str, ...]:
        return ()

    def close(self) -> None:
        self.stop()

    # -- fault injection (tests) ----------------------------------------------
    def inject_fault(self, message: str) -> None:
        """Make every following ``read`` raise ``SensorFault(message)`` until the next ``start``."""
        with self._lock:
            self._fault = message

    def stall(self) -> None:
        """Deliver no more samples until the next ``start`` (a sensor gone silent)."""
        with self._lock:
            self._stalled = True

    def __enter__(self) -> "SimulatedAngleSensor":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
