"""systemd notification protocol (sd_notify) over the Unix datagram socket in $NOTIFY_SOCKET.

A few lines instead of a dependency: the protocol is one datagram of
``KEY=VALUE`` lines. Outside systemd (no NOTIFY_SOCKET) every call is a no-op.

Watchdog: systemd sets WATCHDOG_USEC (and WATCHDOG_PID) when the unit has
``WatchdogSec=``; the daemon must send ``WATCHDOG=1`` more often than that.
``Notifier.watchdog_due()`` tells the main loop when (every half period).
"""

from __future__ import annotations

import os
import socket
import time
from typing import Callable, Mapping


class Notifier:
    def __init__(self, environ: Mapping[str, str] | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        env = os.environ if environ is None else environ
        addr = env.get("NOTIFY_SOCKET") or None
        if addr and addr.startswith("@"):  # abstract namespace
            addr = "\0" + addr[1:]
        self._addr = addr
        self._sock: socket.socket | None = None
        self._clock = clock
        usec = env.get("WATCHDOG_USEC")
        pid = env.get("WATCHDOG_PID")
        period = None
        if usec and usec.isdigit() and int(usec) > 0 and (not pid or pid == str(os.getpid())):
            period = int(usec) / 1e6
        #: the watchdog period systemd expects, s (None: no watchdog)
        self.watchdog_period: float | None = period
        self._last_ping = float("-inf")

    @property
    def enabled(self) -> bool:
        return self._addr is not None

    def send(self, **fields: str | int) -> bool:
        """Send one notification (e.g. READY=1, STATUS=...). False when there is no socket or it failed."""
        if self._addr is None:
            return False
        msg = "\n".join(f"{k}={v}" for k, v in fields.items()).encode("utf-8", "replace")
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto(msg, self._addr)
            return True
        except OSError:
            # systemd gone or socket full: the watchdog will tell; never take the daemon down for this
            return False

    def ready(self, status: str = "") -> bool:
        return self.send(READY=1, STATUS=status, MAINPID=os.getpid()) if status else self.send(READY=1, MAINPID=os.getpid())

    def status(self, text: str) -> bool:
        return self.send(STATUS=text)

    def stopping(self, status: str = "stopping") -> bool:
        return self.send(STOPPING=1, STATUS=status)

    def watchdog_due(self) -> bool:
        if self.watchdog_period is None:
            return False
        return self._clock() - self._last_ping >= self.watchdog_period / 2

    @property
    def last_watchdog_ping(self) -> float | None:
        """When the watchdog was last pinged (the clock's s, time.monotonic by default); None: never."""
        return None if self._last_ping == float("-inf") else self._last_ping

    def watchdog(self) -> bool:
        """Ping the watchdog (call only when the main loop is healthy)."""
        self._last_ping = self._clock()
        return self.send(WATCHDOG=1)

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
