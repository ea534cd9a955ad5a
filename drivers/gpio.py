"""What every GPIO device of the appliance shares: one gpiozero device on one pin, put in its safe
state and released by ``close()`` (safe twice), usable as a context manager."""

from __future__ import annotations

import threading
from typing import Any, Callable, Self


class GpioDevice:
    """Base of the push button, the indicator and the solenoid.

    A subclass sets ``_device`` (the gpiozero device) and ``_lock`` (guarding its state) in its
    constructor, and says in ``_make_safe`` what its safe state is.
    """

    _device: Any
    _lock: threading.Lock | threading.RLock
    _closed: bool = False

    @property
    def pin(self) -> Any:
        """The gpiozero pin (on the mock backend a ``MockPin``: tests drive and read it)."""
        return self._device.pin

    def _make_safe(self) -> Callable[[], None] | None:
        """Under the lock, before the pin is released: put the device in its safe state. Returns what to
        call once the lock is released (e.g. listeners told the output went off), or None."""
        return None

    def close(self) -> None:
        """Safe state, then release the pin; safe twice."""
        with self._lock:
            if self._closed:
                return
            after = self._make_safe()
            self._closed = True
        # outside the lock: gpiozero joins the pin's event thread, which may be waiting for the lock
        self._device.close()
        if after is not None:
            after()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
