"""A private asyncio event loop on a daemon thread, for the drivers and servers built on async pymodbus.

The rest of the appliance is threaded and blocking; pymodbus's clients and
servers are asyncio. Each of them owns one ``LoopThread``: ``start()`` runs
the loop, ``call(coro, timeout)`` runs a coroutine on it and waits for the
result (real time), ``submit`` only schedules it, ``stop()`` ends the loop
and joins the thread. ``start`` and ``stop`` are safe twice.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
from typing import Any, Coroutine

log = logging.getLogger("moi.drivers.aioloop")


class LoopThread:
    """An asyncio loop running forever on a daemon thread named ``name``."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            raise RuntimeError(f"{self.name}: the event loop is not started")
        return self._loop

    def start(self, timeout: float = 2.0) -> "LoopThread":
        """Run the loop (returns once it runs, at most ``timeout`` s); nothing happens when it already does."""
        if self.running:
            return self
        loop = asyncio.new_event_loop()
        ready = threading.Event()

        def run() -> None:
            asyncio.set_event_loop(loop)
            loop.call_soon(ready.set)
            try:
                loop.run_forever()
            finally:
                try:
                    loop.run_until_complete(loop.shutdown_asyncgens())
                finally:
                    loop.close()

        loop.set_exception_handler(_OnceAMinute(self.name))
        self._loop = loop
        self._thread = threading.Thread(target=run, name=self.name, daemon=True)
        self._thread.start()
        ready.wait(timeout)
        return self

    def submit(self, coro: Coroutine[Any, Any, Any]) -> concurrent.futures.Future:
        """Schedule ``coro`` on the loop; its future (``result(timeout)`` waits in real time)."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop)

    def call(self, coro: Coroutine[Any, Any, Any], timeout: float = 5.0) -> Any:
        """Run ``coro`` on the loop and wait for its result; raises what it raises, or ``TimeoutError``
        after ``timeout`` s of real time (the coroutine is then cancelled)."""
        fut = self.submit(coro)
        try:
            return fut.result(timeout)
        except concurrent.futures.TimeoutError:
            fut.cancel()
            raise TimeoutError(f"{self.name}: no result within {timeout:g} s") from None

    def start_serving(self, serve: Coroutine[Any, Any, Any], timeout: float = 5.0) -> Any:
        """Start the loop and run ``serve`` (a server's start-up) on it; returns its result. On any
        failure (``TimeoutError`` after ``timeout`` s of real time) the loop is stopped and it re-raises."""
        self.start(timeout)
        try:
            return self.call(serve, timeout)
        except BaseException:
            self.stop()
            raise

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the loop and join the thread (at most ``timeout`` s); safe twice."""
        loop, thread = self._loop, self._thread
        self._loop = None
        self._thread = None
        if loop is None or thread is None:
            return
        if thread.is_alive():
            loop.call_soon_threadsafe(loop.stop)
            thread.join(timeout)
            if thread.is_alive():
                log.warning("%s: the event loop thread did not end within %g s", self.name, timeout)


#: the same asyncio error is logged at most once per this many seconds, s
ERROR_LOG_INTERVAL = 60.0


class _OnceAMinute:
    """The loop's exception handler: asyncio's own report, once per ``ERROR_LOG_INTERVAL`` for each message,
    then a count. Out of descriptors, asyncio reports every failed accept with its traceback: one client
    could fill the disk with them."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._last: dict[str, tuple[float, int]] = {}  # message → (monotonic time logged, repeats since)

    def __call__(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        import time

        key = str(context.get("message", ""))
        now = time.monotonic()
        logged_at, repeats = self._last.get(key, (-float("inf"), 0))
        if now - logged_at < ERROR_LOG_INTERVAL:
            self._last[key] = (logged_at, repeats + 1)
            return
        if len(self._last) > 100:  # messages that name a connection differ each time: keep the table small
            self._last.clear()
        self._last[key] = (now, 0)
        if repeats:
            context = {**context, "message": f"{key} ({repeats} more since the last report)"}
        loop.default_exception_handler(context)
