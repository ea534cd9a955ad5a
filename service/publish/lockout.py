"""Wrong logins counted per key (a source address, or an address and an account together) within a window.

``after`` wrong ones within ``window`` s lock the key for ``seconds`` s. The doors key it so that the network
can never lock an account out alone: the web page by the address and the user name together (and by the
address alone across names), OPC UA by the peer's host. The clock is passed in: tests move it by hand.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

K = TypeVar("K", bound=Hashable)

#: keys remembered at most: the oldest go first (a guesser naming a new user per try fills no memory)
MOST_KEYS = 4096


class Lockouts(Generic[K]):
    """Recent wrong tries per key, and the keys locked out until when."""

    def __init__(self, after: int, window: float, seconds: float, clock: Callable[[], float]) -> None:
        self.after, self.window, self.seconds = after, window, seconds
        self._clock = clock
        self._wrong: dict[K, list[float]] = {}  # key → times of its wrong tries within the window
        self._until: dict[K, float] = {}  # key → when its lockout ends

    def failed(self, key: K) -> bool:
        """Count a wrong try of ``key``; True when it locks the key out now."""
        now = self._clock()
        times = [t for t in self._wrong.pop(key, ()) if now - t < self.window] + [now]
        self._wrong[key] = times  # newest last: the dict's order is the order of the latest tries
        while len(self._wrong) > MOST_KEYS:
            del self._wrong[next(iter(self._wrong))]
        if len(times) >= self.after and self.locked_for(key) == 0:
            self._until[key] = now + self.seconds
            while len(self._until) > MOST_KEYS:
                del self._until[min(self._until, key=self._until.__getitem__)]
            return True
        return False

    def recent(self, key: K) -> int:
        """Wrong tries of ``key`` within the window."""
        now = self._clock()
        return sum(now - t < self.window for t in self._wrong.get(key, ()))

    def locked_for(self, key: K) -> float:
        """How much longer ``key`` is locked out, s (0: not locked)."""
        until = self._until.get(key)
        if until is None:
            return 0.0
        left = until - self._clock()
        if left <= 0:
            del self._until[key]
            return 0.0
        return left

    def locked(self) -> dict[K, float]:
        """Every key locked out now, with the seconds left."""
        return {k: left for k in list(self._until) if (left := self.locked_for(k)) > 0}

    def lift(self, which: Callable[[K], bool]) -> None:
        """Lift the lockouts, and forget the recent wrong tries, of the keys ``which`` picks."""
        for d in (self._wrong, self._until):
            for k in [k for k in d if which(k)]:
                del d[k]

    def hold(self, key: K, seconds: float) -> None:
        """Lock ``key`` out for ``seconds`` more (a lockout kept across a restart)."""
        if seconds > 0:
            self._until[key] = self._clock() + seconds
