"""The operator's push button (gpiozero ``Button``): one press asks for one measurement.

Debouncing is gpiozero's ``bounce_time`` on real pins (gpiozero's mock pins
ignore it: tests drive clean edges). Whether a press is honoured is the
sequencer's decision, not the button's.
"""

from __future__ import annotations

import logging
import threading
from typing import Callable

from gpiozero import Button
from gpiozero.pins import Factory

from .backend import pin_factory as default_factory
from .gpio import GpioDevice
from .settings import ButtonSettings

log = logging.getLogger("moi.drivers.button")


class PushButton(GpioDevice):
    """A momentary push button on a GPIO input.

    pin: BCM number or gpiozero pin name.
    pull_up: True when the button pulls the line to ground (internal pull-up, pressed = low).
    bounce_time: contact bounce suppressed, s (None: none).
    ``when_pressed``: a callable with no arguments, called on the pin's event thread.
    """

    def __init__(self, pin: int | str, *, pull_up: bool = True, bounce_time: float | None = 0.05,
                 pin_factory: Factory | None = None):
        ButtonSettings(pin, pull_up, bounce_time)  # checks them (the config derives its keys from it)
        self._lock = threading.Lock()
        self._when_pressed: Callable[[], None] | None = None
        self.presses = 0
        self._device = Button(pin, pull_up=pull_up, bounce_time=bounce_time,
                              pin_factory=pin_factory or default_factory())
        self._device.when_pressed = self._pressed

    @property
    def is_pressed(self) -> bool:
        return not self._closed and bool(self._device.is_pressed)

    @property
    def when_pressed(self) -> Callable[[], None] | None:
        return self._when_pressed

    @when_pressed.setter
    def when_pressed(self, callback: Callable[[], None] | None) -> None:
        with self._lock:
            self._when_pressed = callback

    def _make_safe(self) -> None:
        self._when_pressed = None  # detached: a press while closing asks for nothing

    def _pressed(self) -> None:
        with self._lock:
            self.presses += 1
            callback = self._when_pressed
        log.info("button pressed (%d)", self.presses)
        if callback is not None:
            callback()
