"""The live streams (``/events``, server-sent events) are counted apart from page requests.

A stream holds its connection for as long as the browser stays on the page: counted with the pages, 64
unauthenticated streams locked everyone out of the page (Measure and Abort included) for as long as they
stayed open. So streams have their own slots (``max_streams``, at most ``max_streams_per_client`` from one
address), the connection cap counts the pages' connections only, and a stream ends after
``stream_lifetime`` (the browser's EventSource opens a new one by itself, after the ``retry`` it was told).
"""

from __future__ import annotations

import threading


class StreamSlots:
    """Slots for live streams: in all, and per client address."""

    def __init__(self, total: int, per_client: int) -> None:
        self.total, self.per_client = total, per_client
        self._open: dict[str, int] = {}
        self._lock = threading.Lock()
        self.refused = 0

    def take(self, client: str) -> str | None:
        """A slot for ``client``'s stream, or why there is none (the stream is then refused)."""
        with self._lock:
            if sum(self._open.values()) >= self.total:
                why = f"{self.total} live streams are open (the limit)"
            elif self._open.get(client, 0) >= self.per_client:
                why = f"{self.per_client} live streams are open from {client} (the limit per client)"
            else:
                self._open[client] = self._open.get(client, 0) + 1
                return None
            self.refused += 1
            return why

    def give_back(self, client: str) -> None:
        with self._lock:
            n = self._open.get(client, 0) - 1
            if n > 0:
                self._open[client] = n
            else:
                self._open.pop(client, None)

    @property
    def open(self) -> int:
        with self._lock:
            return sum(self._open.values())
