"""The one place that decides which GPIO backend (real or mock) the drivers use.

Order: an explicit ``backend`` argument (from the service settings), else the
``GPIOZERO_PIN_FACTORY`` environment variable, else gpiozero's own default
(lgpio on a Pi). ``"mock"`` gives gpiozero's ``MockFactory``: pins that record
every state change with its time (``pin.states``), used by the tests and by
``moi measure --sim``. Drivers never test for mock themselves; they take the
factory returned here.
"""

from __future__ import annotations

import os
import threading
from importlib.metadata import entry_points

from gpiozero import Device
from gpiozero.pins import Factory
from gpiozero.pins.mock import MockFactory

from .errors import DriverConfigError

MOCK = "mock"
_lock = threading.Lock()


def backend_name(backend: str | None = None) -> str:
    """The backend in force: the argument, else $GPIOZERO_PIN_FACTORY, else "default"."""
    return (backend or os.environ.get("GPIOZERO_PIN_FACTORY") or "default").strip()


def is_mock(backend: str | None = None) -> bool:
    return backend_name(backend).lower() == MOCK


def pin_factory(backend: str | None = None) -> Factory | None:
    """The gpiozero pin factory for ``backend`` ("mock", "lgpio", "rpigpio", "pigpio", "native" or None).

    None (no backend named anywhere): gpiozero's own default, which gpiozero itself picks when
    the first device is made with ``pin_factory=None`` (lgpio on a Pi); this returns None then.

    The mock factory is shared process-wide (``gpiozero.Device.pin_factory``)
    so that a test can reach the very pins a driver uses. Unknown names raise
    ``DriverConfigError`` listing the installed backends.
    """
    name = backend_name(backend)
    with _lock:
        if name.lower() == MOCK:
            if not isinstance(Device.pin_factory, MockFactory):
                Device.pin_factory = MockFactory()
            return Device.pin_factory
        if name == "default":
            return Device.pin_factory  # None until gpiozero has chosen its default for the first device
        group = entry_points(group="gpiozero_pin_factories")
        for ep in group:
            if ep.name == name or ep.name == name.lower():
                try:
                    return ep.load()()
                except ImportError as exc:  # a missing Pi library: say which and how to get it
                    raise DriverConfigError(
                        f"GPIO backend {name!r} cannot start ({type(exc).__name__}: {exc}); "
                        "on a Raspberry Pi install the [pi] extra (lgpio), elsewhere use backend 'mock'") from None
                except Exception as exc:  # the library is there but failed: its own reason, not "install it"
                    raise DriverConfigError(
                        f"GPIO backend {name!r} cannot start: {type(exc).__name__}: {exc} (lgpio creates its "
                        "notification pipes in the working directory or $LG_WD, which must be writable; "
                        "the GPIO chip must be accessible to this user)") from None
        known = sorted({ep.name for ep in group})
        raise DriverConfigError(f"unknown GPIO backend {name!r}; expected one of {', '.join(known)}")
