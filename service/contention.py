"""Whether the clients the appliance served during a capture slowed it: the flag ``capture_slowed``.

The servers give way to the sensor while it is read (the web page's and OPC UA's gates), but they share the
processor with its reader: a capture during which requests were served, whose sample rate fell below
``SLOWED_SHARE`` of the median rate of the last ``KEPT`` captures that served none, is flagged. Without such
captures yet there is nothing to compare with, and no flag.
"""

from __future__ import annotations

import statistics
from collections import deque
from typing import Any, Callable, Mapping

#: a capture is slowed below this share of the quiet captures' median sample rate
SLOWED_SHARE = 0.8
#: the quiet captures' rates kept
KEPT = 5


def sample_rate(acquisition: Mapping[str, Any] | None) -> float | None:
    """The sensor's samples per second during the capture (``acquisition.<sensor>.rate_hz``), or None."""
    for part in (acquisition or {}).values():
        rate = part.get("rate_hz") if isinstance(part, Mapping) else None
        if isinstance(rate, (int, float)) and not isinstance(rate, bool) and rate > 0:
            return float(rate)
    return None


class CaptureWatch:
    """``armed()`` when a capture starts, ``slowed(acquisition)`` when its result is stored."""

    def __init__(self, served: Callable[[], int]) -> None:
        self._served = served
        self._at_start: int | None = None
        self._quiet: deque[float] = deque(maxlen=KEPT)

    def armed(self) -> None:
        self._at_start = self._served()

    def slowed(self, acquisition: Mapping[str, Any] | None) -> bool:
        rate = sample_rate(acquisition)
        if rate is None or self._at_start is None:
            return False
        served, self._at_start = self._served() - self._at_start, None
        if served == 0:
            self._quiet.append(rate)
            return False
        return bool(self._quiet) and rate < SLOWED_SHARE * statistics.median(self._quiet)
