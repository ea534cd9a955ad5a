"""The settings of the GPIO devices, checked in one place (no gpiozero import here).

Each driver validates its arguments by building its settings object, and the
appliance configuration (``[hardware.solenoid]``, ``[hardware.button]``,
``[hardware.indicator]``) derives its keys and defaults from the same
dataclasses, so a limit such as the solenoid's longest pulse is written once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .errors import DriverConfigError

#: no configuration may allow a longer pulse than this, s (release solenoids are rated for short duty)
ABSOLUTE_MAX_ON_TIME = 5.0

#: what an indicator can be
INDICATOR_KINDS = ("led", "buzzer")


def check_pin(pin: Any, what: str) -> int | str:
    """A GPIO pin number (BCM, >= 0) or a gpiozero pin name such as "GPIO17" or "BOARD11"."""
    if isinstance(pin, bool) or not isinstance(pin, (int, str)) or (isinstance(pin, int) and pin < 0) or pin == "":
        raise DriverConfigError(f"{what}: pin must be a BCM number >= 0 or a name like 'GPIO17', got {pin!r}")
    return pin


def _is_time(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


@dataclass(frozen=True)
class SolenoidSettings:
    """pin: BCM number or gpiozero pin name. active_high: a high level energises the coil.
    max_on_time: hard limit of one pulse, s (0 < max_on_time <= 5)."""

    pin: int | str
    active_high: bool = True
    max_on_time: float = 0.5

    def __post_init__(self) -> None:
        check_pin(self.pin, "solenoid")
        if not (_is_time(self.max_on_time) and 0 < self.max_on_time <= ABSOLUTE_MAX_ON_TIME):
            raise DriverConfigError(
                f"solenoid: max_on_time must be a time in (0, {ABSOLUTE_MAX_ON_TIME:g}] s, got {self.max_on_time!r}")


@dataclass(frozen=True)
class ButtonSettings:
    """pin: BCM number or gpiozero pin name. pull_up: pressed pulls the line low (internal pull-up).
    bounce_time: contact bounce suppression, s in (0, 1] (None: none)."""

    pin: int | str
    pull_up: bool = True
    bounce_time: float | None = 0.05

    def __post_init__(self) -> None:
        check_pin(self.pin, "button")
        if self.bounce_time is not None and not (_is_time(self.bounce_time) and 0 < self.bounce_time <= 1):
            raise DriverConfigError(f"button: bounce_time must be None or a time in (0, 1] s, got {self.bounce_time!r}")


@dataclass(frozen=True)
class IndicatorSettings:
    """pin: BCM number or gpiozero pin name. kind: "led" or "buzzer". active_high: a high level lights/sounds it."""

    pin: int | str
    kind: str = "led"
    active_high: bool = True

    def __post_init__(self) -> None:
        check_pin(self.pin, "indicator")
        if self.kind not in INDICATOR_KINDS:
            raise DriverConfigError(f"indicator: kind must be one of {', '.join(INDICATOR_KINDS)}, got {self.kind!r}")
