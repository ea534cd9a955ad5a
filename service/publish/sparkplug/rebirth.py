"""Rebirth requests, at most one birth per interval.

A host application asks for ``Node Control/Rebirth`` when it has lost track of the node (it came up after the
birth, it saw a gap in ``seq``, it does not know an alias); what it needs is one birth after its request, not
one per request. Requests within ``interval`` of the last birth are answered together by one birth at the end
of the interval, so any number of requests (several hosts, a host in a loop, a hostile client) costs at most one
NBIRTH/DBIRTH pair per interval, and no request goes unanswered.
"""

from __future__ import annotations

import time
from typing import Callable


class BirthLimit:
    """When the next birth may go. Not thread-safe: one thread asks (the node's control thread)."""

    def __init__(self, interval: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.interval = interval
        self._clock = clock
        self._last = -float("inf")  # the last birth, by clock
        self._pending = False  # a request waits for the end of the interval
        self.requests = 0  # Rebirth requests since start
        self.deferred = 0  # of them, answered by a later birth together with others

    def request(self) -> bool:
        """A Rebirth request: True when the birth may go now, else False (it goes at ``due_in()``)."""
        self.requests += 1
        if not self._pending and self._clock() - self._last >= self.interval:
            return True
        self._pending = True
        self.deferred += 1
        return False

    def born(self) -> None:
        """A birth went out (for a request, a connection or the host coming online): it answers every request so far."""
        self._last = self._clock()
        self._pending = False

    def forget(self) -> None:
        """The waiting requests are answered otherwise (their birth is going out, or no session is there to birth)."""
        self._pending = False

    def due_in(self) -> float | None:
        """Seconds until the waiting requests' birth is due (0: now); None when none waits."""
        if not self._pending:
            return None
        return max(0.0, self._last + self.interval - self._clock())
