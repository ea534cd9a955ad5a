"""The live streams (``/events``, server-sent events) are counted apart from page requests.

A stream holds its connection for as long as the browser stays on the page: counted with the pages, 64
unauthenticated streams locked everyone out of the page (Measure and Abort included) for as long as they
stayed open. So streams have their own slots (``max_streams``, at most ``max_streams_per_client`` from one
address), the connection cap counts the pages' connections only, and a stream ends after
``stream_lifetime`` (the browser's EventSource opens a new one by itself, after the ``retry`` it was told).

No small set of addresses can take every slot: when all are taken, an address holding fewer than its share
(the slots over the addresses holding streams, the newcomer's counted, one at least) gets one, and the oldest
stream of the address holding the most yields it; a logged-in user's stream also makes the oldest anonymous
stream yield. An anonymous newcomer never makes a logged-in user's stream yield. A yielded stream ends at
once; its browser asks again and is refused while its address holds its share.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass(eq=False)
class Stream:
    """One live stream's slot: from where, whether its viewer is logged in, and how to end it early."""

    client: str
    logged_in: bool
    end: Callable[[], None] = field(repr=False)
    number: int = 0  # the order streams were opened in: the lowest is the oldest


class StreamSlots:
    """Slots for live streams: in all, and per client address, with a share per address."""

    def __init__(self, total: int, per_client: int) -> None:
        self.total, self.per_client = total, per_client
        self._streams: list[Stream] = []  # oldest first
        self._numbers = itertools.count()
        self._lock = threading.Lock()
        self.refused = 0
        self.yielded = 0  # streams ended early to give their slot to another address or a logged-in user

    def take(self, client: str, logged_in: bool = False, end: Callable[[], None] = lambda: None) -> Stream | str:
        """A slot for ``client``'s stream (``end`` ends it early, should it yield), or why there is none (the
        stream is then refused)."""
        with self._lock:
            mine = [s for s in self._streams if s.client == client]
            victim: Stream | None = None
            if len(mine) >= self.per_client:
                # only a login makes room among its address's streams (tabs that took turns would never settle)
                victim = _oldest(mine, anonymous_only=True) if logged_in else None
                if victim is None:
                    return self._refuse(f"{self.per_client} live streams are open from {client} (the limit per "
                                        "client)")
            elif len(self._streams) >= self.total:
                victim = self._to_yield(client, len(mine), logged_in)
                if victim is None:
                    return self._refuse(f"{self.total} live streams are open (the limit) and none yields: {client} "
                                        "holds its share, or the others are logged-in users'")
            if victim is not None:
                self._streams.remove(victim)
                self.yielded += 1
            stream = Stream(client, logged_in, end, next(self._numbers))
            self._streams.append(stream)
        if victim is not None:
            victim.end()
        return stream

    def _refuse(self, why: str) -> str:
        self.refused += 1
        return why

    def _to_yield(self, client: str, holds: int, logged_in: bool) -> Stream | None:
        """The stream that yields its slot to a newcomer from ``client`` (holding ``holds``) when all are taken."""
        counts: dict[str, int] = {}
        for s in self._streams:
            counts[s.client] = counts.get(s.client, 0) + 1
        share = max(1, self.total // len(counts.keys() | {client}))
        if holds < share:
            for address in sorted(counts, key=lambda a: -counts[a]):  # the address holding the most first
                if counts[address] > holds + 1 and (victim := _oldest(
                        [s for s in self._streams if s.client == address], anonymous_only=not logged_in)):
                    return victim
        return _oldest(self._streams, anonymous_only=True) if logged_in else None

    def give_back(self, stream: Stream) -> None:
        """The stream ended (a stream that yielded has already given its slot back)."""
        with self._lock:
            if stream in self._streams:
                self._streams.remove(stream)

    @property
    def open(self) -> int:
        with self._lock:
            return len(self._streams)


def _oldest(streams: list[Stream], anonymous_only: bool) -> Stream | None:
    """The oldest anonymous stream of ``streams``, else (unless ``anonymous_only``) the oldest logged-in one;
    None: none."""
    anonymous = [s for s in streams if not s.logged_in]
    pool = anonymous or ([] if anonymous_only else streams)
    return min(pool, key=lambda s: s.number) if pool else None
