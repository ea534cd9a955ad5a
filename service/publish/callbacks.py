"""The guard of a paho callback, shared by the publishers that hold a paho client (MQTT, Sparkplug B).

An exception that escaped a paho callback would end paho's network thread: no more commands,
acknowledgements or reconnects. The guard logs it, counts it on the publisher (``callback_errors``) and
keeps it as the publisher's ``last_error``, and the connection goes on.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from typing import Any


def never_raises(log: logging.Logger, label: str) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Decorate a publisher's paho callback; the failure goes to the publisher's ``log``, named by ``label``."""

    def guard(callback: Callable[..., None]) -> Callable[..., None]:
        @functools.wraps(callback)
        def guarded(self: Any, *args: Any) -> None:
            try:
                callback(self, *args)
            except Exception as exc:  # a callback must never end the network thread
                self.callback_errors += 1
                self.last_error = f"{callback.__name__}: {type(exc).__name__}: {exc}"
                log.exception("%s: %s failed (ignored; the connection goes on)", label, callback.__name__)

        return guarded

    return guard
