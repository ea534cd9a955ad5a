"""Optional status output: an LED or a buzzer on one GPIO line.

``show(state)`` maps the sequencer's state names to a pattern, so the
operator sees (or hears) ready / busy / fault without a screen:

    LED:    IDLE steady on (ready) · busy slow blink · FAULT fast blink ·
            BLOCKED a short flash every 2 s (IDLE, but the calibration refuses Measure)
    buzzer: one short beep on PUBLISHING (result ready) · three long beeps on FAULT · silent while busy ·
            two long beeps on BLOCKED (shown again at each refused press)
"""

from __future__ import annotations

import threading

from gpiozero import DigitalOutputDevice
from gpiozero.pins import Factory

from .backend import pin_factory as default_factory
from .gpio import GpioDevice
from .settings import IndicatorSettings

_BUSY = {"ARMED", "RELEASING", "CAPTURING", "IDENTIFYING"}


class Indicator(GpioDevice):
    """A status LED or buzzer.

    pin: BCM number or gpiozero pin name; kind: "led" | "buzzer";
    active_high: True when a high level lights/sounds it.
    """

    def __init__(self, pin: int | str, *, kind: str = "led", active_high: bool = True,
                 pin_factory: Factory | None = None):
        IndicatorSettings(pin, kind, active_high)  # checks them (the config derives its keys from it)
        self.kind = kind
        self.shown: str | None = None
        self._lock = threading.Lock()
        self._device = DigitalOutputDevice(pin, active_high=active_high, initial_value=False,
                                           pin_factory=pin_factory or default_factory())

    @property
    def is_active(self) -> bool:
        return not self._closed and bool(self._device.value)

    def show(self, state: str) -> None:
        """Show a sequencer state name (unknown names switch it off)."""
        with self._lock:
            if self._closed:
                return
            self.shown = state
            d = self._device
            if self.kind == "led":
                if state == "IDLE":
                    d.on()
                elif state in _BUSY or state == "PUBLISHING":
                    d.blink(on_time=0.5, off_time=0.5)
                elif state == "FAULT":
                    d.blink(on_time=0.1, off_time=0.1)
                elif state == "BLOCKED":
                    d.blink(on_time=0.1, off_time=1.9)
                else:
                    d.off()
            else:
                if state == "PUBLISHING":
                    d.blink(on_time=0.1, off_time=0.1, n=1)
                elif state == "FAULT":
                    d.blink(on_time=0.4, off_time=0.2, n=3)
                elif state == "BLOCKED":
                    d.blink(on_time=0.6, off_time=0.3, n=2)
                elif state in _BUSY:
                    d.off()
                # IDLE right after PUBLISHING leaves the beep to finish

    def off(self) -> None:
        with self._lock:
            if not self._closed:
                self._device.off()

    def _make_safe(self) -> None:
        self._device.off()
