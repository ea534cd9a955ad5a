"""The daemon's log: what a reader of the journal needs, not what a library or a client repeats.

``RepeatFilter`` lets a line through once per ``REPEAT_INTERVAL`` and counts the ones it held back; the next
one let through says how many. Lines are alike when their text is the same; a library's lines (anything but
``moi.*``) when their template is, so that the same complaint about another peer's address or port counts
as a repeat. ``quiet_libraries`` keeps the libraries' chatter (asyncua writes some 1,100 INFO lines per
start and 10 per connection) at WARNING unless the daemon logs at DEBUG.
"""

from __future__ import annotations

import logging
import time
from typing import Callable

#: an alike line is let through at most once per this many seconds, s
REPEAT_INTERVAL = 60.0
#: at most this many different lines are remembered (the least recently seen is forgotten)
REMEMBERED = 512
#: the libraries whose INFO lines are chatter: at WARNING unless the daemon logs at DEBUG
CHATTY = ("asyncua",)


class RepeatFilter(logging.Filter):
    """A handler's filter: alike lines once per ``interval``, with the count of those held back."""

    def __init__(self, interval: float = REPEAT_INTERVAL, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.interval, self._clock = interval, clock
        self._seen: dict[tuple, list[float]] = {}  # key → [last let through, held back since]

    @staticmethod
    def _key(record: logging.LogRecord) -> tuple:
        own = record.name == "moi" or record.name.startswith("moi.")
        return record.name, record.levelno, record.getMessage() if own else str(record.msg)

    def filter(self, record: logging.LogRecord) -> bool:
        key, now = self._key(record), self._clock()
        seen = self._seen.pop(key, None)
        if seen is not None and now - seen[0] < self.interval:
            seen[1] += 1
            self._seen[key] = seen
            return False
        held = int(seen[1]) if seen is not None else 0
        self._seen[key] = [now, 0]
        while len(self._seen) > REMEMBERED:
            self._seen.pop(next(iter(self._seen)))
        if held:
            record.msg = f"{record.getMessage()} (and {held} more like it in the last {self.interval:g} s)"
            record.args = None
        return True


def quiet_libraries(level: int) -> None:
    """The chatty libraries at WARNING unless ``level`` is DEBUG."""
    for name in CHATTY:
        logging.getLogger(name).setLevel(logging.NOTSET if level <= logging.DEBUG else logging.WARNING)


def install(level: int) -> None:
    """On every handler of the root logger: the repeat filter; the chatty libraries quiet."""
    for handler in logging.getLogger().handlers:
        if not any(isinstance(f, RepeatFilter) for f in handler.filters):
            handler.addFilter(RepeatFilter())
    quiet_libraries(level)


class Throttle:
    """A logger's lines that a client can make it repeat (one per message it sends): each template at most once
    per ``interval``, with the count of those held back since."""

    def __init__(self, logger: logging.Logger, interval: float = REPEAT_INTERVAL,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.logger, self.interval, self._clock = logger, interval, clock
        self._seen: dict[str, list[float]] = {}  # template → [last logged, held back since]

    def __call__(self, level: int, template: str, *args: object) -> None:
        now = self._clock()
        seen = self._seen.setdefault(template, [-float("inf"), 0])
        if now - seen[0] < self.interval:
            seen[1] += 1
            return
        held = int(seen[1])
        seen[0], seen[1] = now, 0
        more = f" (and {held} more like it in the last {self.interval:g} s)" if held else ""
        self.logger.log(level, template + more, *args)
