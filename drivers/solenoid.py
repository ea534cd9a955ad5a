"""The release solenoid: one GPIO output that holds the pendulum until pulsed.

Safety rules kept here, not left to callers:

* off (de-energised) on construction, on ``close()``, on leaving a ``with``
  block and if anything raises while switching it on;
* the only way on is ``pulse(duration)``, and the pulse is cut by a timer
  after ``min(duration, max_on_time)`` s of real time, whatever the caller asks
  (a coil left on overheats, and a stuck release would pin the pendulum);
* no second pulse while energised.

The pin is a gpiozero ``DigitalOutputDevice`` from ``drivers.backend``; on the
mock backend ``solenoid.pin.states`` records every on/off with its duration.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Callable

from gpiozero import DigitalOutputDevice
from gpiozero.pins import Factory

from .backend import pin_factory as default_factory
from .errors import DeviceFault
from .gpio import GpioDevice
from .settings import ABSOLUTE_MAX_ON_TIME, SolenoidSettings  # noqa: F401  (re-exported)

log = logging.getLogger("moi.drivers.solenoid")

class Solenoid(GpioDevice):
    """Release solenoid on a GPIO line.

    pin: BCM number or gpiozero pin name.
    active_high: True when a high level energises the coil (driver board dependent).
    max_on_time: hard limit of one pulse, s (0 < max_on_time <= 5).
    pin_factory: gpiozero factory; None asks ``drivers.backend``.
    """

    def __init__(self, pin: int | str, *, active_high: bool = True, max_on_time: float = 0.5,
                 pin_factory: Factory | None = None):
        SolenoidSettings(pin, active_high, max_on_time)  # checks them (the config derives its keys from it)
        self.max_on_time = float(max_on_time)
        self._lock = threading.RLock()
        self._listeners: list[Callable[[bool], None]] = []
        self._timer: threading.Timer | None = None
        self._generation = 0
        self._off_event = threading.Event()
        self._off_event.set()
        self._on_since: float | None = None
        self.pulses = 0
        self._device = DigitalOutputDevice(pin, active_high=active_high, initial_value=False,
                                           pin_factory=pin_factory or default_factory())
        self._device.off()

    # -- state -------------------------------------------------------------------
    @property
    def is_active(self) -> bool:
        """True while the coil is energised."""
        with self._lock:
            return not self._closed and bool(self._device.value)

    def add_listener(self, callback: Callable[[bool], None]) -> Callable[[], None]:
        """Call ``callback(active)`` after each switch on (True) and off (False); returns a remover.

        Called on the thread that switched (the caller's or the cut-off timer's).
        """
        with self._lock:
            self._listeners.append(callback)

        def remove() -> None:
            with self._lock:
                if callback in self._listeners:
                    self._listeners.remove(callback)
        return remove

    # -- actions -----------------------------------------------------------------
    def pulse(self, duration: float) -> float:
        """Energise for ``duration`` s, cut after at most ``max_on_time`` s; returns the granted time, s.

        Never blocks. Infinite or over-long requests are clamped, not refused;
        a negative or NaN duration is a caller bug (ValueError). Raises
        ``DeviceFault`` if already energised or closed.
        """
        if not isinstance(duration, (int, float)) or math.isnan(duration) or duration <= 0:
            raise ValueError(f"solenoid pulse duration must be > 0 s, got {duration!r}")
        granted = min(float(duration), self.max_on_time)
        with self._lock:
            if self._closed:
                raise DeviceFault("solenoid: pulse requested after close()")
            if self._device.value:
                raise DeviceFault("solenoid: pulse requested while already energised")
            self._generation += 1
            generation = self._generation
            try:
                self._off_event.clear()
                self._device.on()
                self._on_since = time.monotonic()
                timer = threading.Timer(granted, self._cut, args=(generation,))
                timer.daemon = True
                timer.name = "moi-solenoid-cutoff"
                self._timer = timer
                timer.start()
            except BaseException:
                self._switch_off()
                raise
            self.pulses += 1
        self._notify(True)
        return granted

    def off(self) -> None:
        """De-energise now (idempotent, safe after close)."""
        with self._lock:
            was_on = self._switch_off()
        if was_on:
            self._notify(False)

    def wait_off(self, timeout: float | None = None) -> bool:
        """Block until the coil is off (True) or ``timeout`` s of real time pass (False)."""
        return self._off_event.wait(timeout)

    def _make_safe(self) -> Callable[[], None] | None:
        if self._switch_off():
            return lambda: self._notify(False)
        return None

    def __repr__(self) -> str:
        state = "closed" if self._closed else ("on" if self.is_active else "off")
        return f"<Solenoid {state}, max_on_time={self.max_on_time:g} s>"

    # -- internals -----------------------------------------------------------------
    def _switch_off(self) -> bool:
        """Off under the lock; returns whether it was on."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        was_on = False
        if not self._closed:
            was_on = bool(self._device.value)
            self._device.off()
        if was_on and self._on_since is not None:
            log.debug("solenoid off after %.4f s", time.monotonic() - self._on_since)
        self._on_since = None
        self._off_event.set()
        return was_on

    def _cut(self, generation: int) -> None:
        with self._lock:
            if generation != self._generation:
                return  # a stale timer of an earlier pulse
            was_on = self._switch_off()
        if was_on:
            self._notify(False)

    def _notify(self, active: bool) -> None:
        with self._lock:
            listeners = list(self._listeners)
        for callback in listeners:
            try:
                callback(active)
            except Exception:  # an observer (the simulated rig, a logger) must not keep the coil on
                log.exception("solenoid listener %r failed", callback)
