"""The capture comes first: while the sensor is read, pages are answered one at a time and only in a share
of the web thread's time.

The sensor of a capture is read by threads of the daemon's process, and the web's thread is one more
thread of it: whatever a page costs there holds the interpreter lock against the sensor's reader. Four
anonymous clients looping on the history page dropped a simulated encoder capture from 78 to 23
samples/s, with a read time-out, although each page takes only milliseconds (with this gate: 69–76
samples/s against 77–85 alone, same run). So while a capture is in
progress every page request waits for the one before it, and after it the gate stays closed long enough
that pages take at most ``CAPTURE_WEB_SHARE`` of the web thread's time. Clients are slowed, never refused,
and outside a capture nothing changes. The live stream (what the operator watches during the capture) and
actions (which need a token, and must not wait behind a flood: Abort) pass without waiting.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any, Callable

from aiohttp import web

from service.states import STATES

#: the sequencer states in which the sensor is being read
CAPTURE_STATES = tuple(name for name, s in STATES.items() if s.capturing)


def sensor_is_read(appliance: Any) -> bool:
    """Whether the appliance's sequencer is in a state in which the sensor is being read."""
    seq = appliance.sequencer
    return seq is not None and seq.state.value in CAPTURE_STATES
#: while a capture is in progress, the share of the web thread's CPU time that pages may take at most
CAPTURE_WEB_SHARE = 0.1
#: a page's pause after it, s, at most (a page that took long is not made to block the next for minutes)
MAX_PAUSE = 2.0
#: requests that never wait: the live stream of the swing
UNGATED_PATHS = ("/events",)


class CaptureFirst:
    """aiohttp middleware: pages wait their turn while ``capturing()`` says the sensor is being read."""

    def __init__(self, capturing: Callable[[], bool], share: float = CAPTURE_WEB_SHARE) -> None:
        if not 0 < share <= 1:
            raise ValueError(f"share must be in (0, 1], got {share!r}")
        self.capturing = capturing
        self.share = share
        self._gate: asyncio.Lock | None = None
        self.gated = 0  # requests that went through the gate during a capture

    @web.middleware
    async def middleware(self, request: web.Request, handler: Any) -> web.StreamResponse:
        if request.method not in ("GET", "HEAD") or request.path in UNGATED_PATHS or not self.capturing():
            return await handler(request)
        if self._gate is None:  # made on the web loop, where it is used
            self._gate = asyncio.Lock()
        async with self._gate:
            self.gated += 1
            # the web thread's own CPU time: an await on the child process (an export) costs the sensor nothing
            spent = time.thread_time()
            try:
                return await handler(request)
            finally:
                spent = time.thread_time() - spent
                await asyncio.sleep(min(MAX_PAUSE, spent * (1.0 / self.share - 1.0)))
