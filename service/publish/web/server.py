"""The web server inside the daemon: aiohttp in its own thread and event loop.

Threads: the daemon's main loop delivers sequencer events (``on_state``) and
stored measurements (``on_result``); both only hand over to this
server's loop or to the plot worker and never block. Handlers read the store
(one short SQLite query each) and the appliance's live status; what takes
longer (exports, a trace as CSV, a plot drawn again) is made in a child process
(``child.ChildWork``), never on a thread of the process that reads the sensor;
actions go through the daemon's command queue like the button, Modbus and MQTT.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import errno
import logging
import threading
import time
from typing import TYPE_CHECKING, Any

from aiohttp import web

from drivers.aioloop import LoopThread
from service.errors import AddressInUse, StartupError
from service.publish.port import ApplianceView, Publisher

from .auth import LOCKOUT_FILE_NAME, Guard, read_token, read_users
from .child import ChildWork
from .priority import sensor_is_read
from .settings import DEFAULT_TOKEN_FILE_NAME, PLOT_NAME, WebSettings
from .streams import StreamSlots
from .views import Views

if TYPE_CHECKING:  # pragma: no cover
    from firmware_host import Event, Measurement

log = logging.getLogger("moi.web")

#: plots waiting to be drawn at most; a measurement stored beyond them gets its plot when it is asked for
MAX_PENDING_PLOTS = 8
#: the latest results whose fit the live page can draw over the swing
MAX_FITS = 4
#: points of such a fit at most
FIT_POINTS = 1500
#: at most one "connections refused" line per this many seconds, s
REFUSED_LOG_INTERVAL = 60.0


class _Refuse(asyncio.Protocol):
    """A connection beyond the limit: closed as soon as it is accepted."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)  # a TCP connection: it can be aborted
        transport.abort()


class WebServer(Publisher):
    """Serves the pages of ``appliance`` on ``settings.host``:``settings.port`` (``start`` / ``stop``)."""

    NAME = "web"

    @classmethod
    def build(cls, settings: WebSettings, appliance: ApplianceView) -> "WebServer":
        return cls(appliance, settings)

    def __init__(self, appliance: ApplianceView, settings: WebSettings) -> None:
        self.appliance = appliance
        self.settings = settings
        token_file = settings.token_file or str(appliance.config.state_dir / DEFAULT_TOKEN_FILE_NAME)
        self.token_file = token_file
        users = read_users(settings.users_file) if settings.users_file else None
        self.guard = Guard(read_token(token_file, create=settings.token_file is None), users=users,
                           lockout_file=appliance.config.state_dir / LOCKOUT_FILE_NAME)
        self.bound_port: int | None = None
        self._io = LoopThread("moi-web")
        self._runner: web.AppRunner | None = None
        self._listener: asyncio.AbstractServer | None = None
        self.connections_refused = 0
        self.streams = StreamSlots(settings.max_streams, settings.max_streams_per_client)
        self._refused_logged_at = -float("inf")
        self._listeners: set[asyncio.Queue] = set()
        self._plotter = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="moi-plot")
        self._plots: dict[str, concurrent.futures.Future] = {}
        self._fits: dict[str, dict[str, Any]] = {}
        self._plots_lock = threading.Lock()
        self.child = ChildWork()
        self.views = Views(self)

    # --- life cycle ---------------------------------------------------------------
    @property
    def url(self) -> str:
        host = self.settings.host
        shown = "127.0.0.1" if host in ("0.0.0.0", "") else ("[::1]" if host == "::" else host)
        return f"http://{shown}:{self.bound_port or self.settings.port}/"

    def start(self, timeout: float = 10.0) -> None:
        """Listen (StartupError when the address is taken or not allowed) and serve on the web loop thread."""
        self._io.start()
        try:
            self._io.call(self._serve(), timeout)
        except (OSError, TimeoutError) as exc:
            self.stop()
            s = self.settings
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            message = f"cannot serve the web page on {s.host}:{s.port}: {why}"
            if isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE:
                raise AddressInUse(f"{message} (another program listens there)", s.port) from None
            raise StartupError(f"{message} (address in use, or no permission)") from None
        log.info("web page on %s (actions need the token in %s)", self.url, self.token_file)

    async def _serve(self) -> None:
        # aiohttp's keep-alive timer starts when a connection opens and is renewed only by an answer: as
        # request_timeout it closes a client that trickles its headers (slowloris) as well as an idle one
        runner = web.AppRunner(self.views.application(), access_log=None, handle_signals=False, shutdown_timeout=1.0,
                               keepalive_timeout=self.settings.request_timeout)
        await runner.setup()
        try:
            # the backlog is also how many connections asyncio accepts in one go before it closes any: at
            # max_connections a burst holds at most twice that many descriptors, never the process's last
            self._listener = await asyncio.get_running_loop().create_server(
                self._protocol, self.settings.host, self.settings.port, reuse_address=True,
                backlog=self.settings.max_connections)
        except BaseException:
            await runner.cleanup()
            raise
        self._runner = runner
        self.bound_port = self._listener.sockets[0].getsockname()[1]

    def _protocol(self) -> asyncio.BaseProtocol:
        """aiohttp's protocol for a new connection, or one that closes it at once beyond ``max_connections``:
        every descriptor a client can hold here is one the process may lack for the sensor or the store."""
        assert self._runner is not None and self._runner.server is not None
        # the live streams have slots of their own (``streams``): they do not take the pages' connections
        if len(self._runner.server.connections) - self.streams.open < self.settings.max_connections:
            return self._runner.server()
        self.connections_refused += 1
        now = time.monotonic()
        if now - self._refused_logged_at > REFUSED_LOG_INTERVAL:
            self._refused_logged_at = now
            log.warning("web: %d connections open (the limit); closing new ones (%d so far)",
                        self.settings.max_connections, self.connections_refused)
        return _Refuse()

    async def _close(self) -> None:
        for q in list(self._listeners):
            q.put_nowait(None)  # ends every live stream
        if self._listener is not None:
            self._listener.close()  # no new connections; the open ones are shut down by the runner
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None
        self._listener = None

    def alive(self) -> bool:
        return self._io.running

    def failure(self) -> str | None:
        return None if self.alive() else "the web server thread stopped"

    def where(self) -> str:
        return f"web page {self.url}"

    def capture_requests(self) -> int:
        return self.views.capture_first.gated

    def stop(self, timeout: float = 5.0) -> None:
        """Close the live streams and the server, end the loop thread, let a plot in progress finish; safe twice."""
        if self._io.running:
            try:
                self._io.call(self._close(), timeout)
            except Exception:  # stopping: the loop goes whatever happened
                log.exception("web server shutdown failed")
        self._io.stop()
        self._plotter.shutdown(wait=True, cancel_futures=True)
        self.child.close()

    # --- from the daemon's main loop (never block) -----------------------------------
    def on_state(self, message: Any, event: "Event | None") -> None:
        """A sequencer transition: pushed to every open page at once."""
        if event is not None:
            self.on_event(event)

    def on_event(self, event: "Event") -> None:
        msg = self.views.live.event_message(event)
        def push() -> None:
            for q in self._listeners:
                q.put_nowait(msg)
        self._call(push)

    def on_result(self, stored: Any, measurement: "Measurement") -> None:
        """A measurement was stored: draw its plot once, in the plot worker, and keep it with it."""
        self.measurement_stored(measurement, stored)

    def measurement_stored(self, m: "Measurement", stored: Any = None) -> None:
        self._keep_fit(m)
        with self._plots_lock:
            behind = len(self._plots)
        if behind >= MAX_PENDING_PLOTS:
            # measurements come faster than plots are drawn (a large simulated time scale): each waiting plot
            # holds its result's arrays; this one is drawn from the stored trace when a page asks for it
            log.debug("plot of %s not drawn now: %d plots waiting", m.id, behind)
            return

        def draw() -> bytes:
            # matplotlib holds the interpreter lock for a good part of a second: in the child process, where
            # it cannot delay the sensor's reader of the next capture
            from service.publish.plot import render_png

            from ..quality import plot_labels
            unit, source = plot_labels(stored, m.result, self.appliance.config.simulated,
                                       self.settings.display_unit)
            return self.child.call(render_png, m.result, unit, source)

        self.submit_plot(m.id, draw)

    def _keep_fit(self, m: "Measurement") -> None:
        """The fit and its residual of the latest results, thinned to at most FIT_POINTS points, for the live page
        to draw over the swing it just showed (times from the trace's first sample, s; angles, rad)."""
        try:
            a = m.result.arrays
            t, fitted, residual, t0 = a["t"], a["fitted"], a["residual"], float(a["trace_t"][0])
        except (AttributeError, KeyError, IndexError, TypeError):  # a result without arrays: nothing to draw
            return
        step = max(1, len(t) // FIT_POINTS)
        fit = {"t": [round(float(x) - t0, 4) for x in t[::step]], "fitted": [round(float(x), 6) for x in fitted[::step]],
               "residual": [round(float(x), 7) for x in residual[::step]], "unit": "rad", "time_unit": "s"}
        with self._plots_lock:
            self._fits[m.id] = fit
            while len(self._fits) > MAX_FITS:
                self._fits.pop(next(iter(self._fits)))

    def fit(self, uuid: str) -> dict[str, Any] | None:
        with self._plots_lock:
            return self._fits.get(uuid)

    def submit_plot(self, uuid: str, make_png) -> concurrent.futures.Future:
        """Keep the PNG ``make_png()`` draws with the measurement ``uuid`` (once, however often asked)."""
        with self._plots_lock:
            fut = self._plots.get(uuid)
            if fut is None:
                fut = self._plotter.submit(self._draw, uuid, make_png)
                self._plots[uuid] = fut
        return fut

    def _draw(self, uuid: str, make_png) -> bytes:
        try:
            self._wait_for_no_capture()
            png = make_png()
            store = self.appliance.store
            if store is not None:
                store.put_attachment(uuid, PLOT_NAME, png, "image/png")
            return png
        finally:
            with self._plots_lock:
                self._plots.pop(uuid, None)

    def _wait_for_no_capture(self, limit: float = 300.0) -> None:
        """Draw between captures: the child process that draws takes a core for a good part of a second, which
        on a busy device would add jitter to the sample times of a capture that started right after the last
        result."""
        deadline = time.monotonic() + limit
        while self._io.running and time.monotonic() < deadline:
            if not sensor_is_read(self.appliance):
                return
            time.sleep(0.1)

    def _call(self, fn) -> None:
        if not self._io.running:
            return
        with contextlib.suppress(RuntimeError):  # stopping
            self._io.loop.call_soon_threadsafe(fn)

    # --- for the views -----------------------------------------------------------------
    def listen(self) -> asyncio.Queue:
        q: asyncio.Queue = asyncio.Queue()
        self._listeners.add(q)
        return q

    def unlisten(self, q: asyncio.Queue) -> None:
        self._listeners.discard(q)

    def plot_future(self, uuid: str) -> concurrent.futures.Future | None:
        with self._plots_lock:
            return self._plots.get(uuid)

    def stats(self) -> dict[str, Any]:
        server = self._runner.server if self._runner is not None else None
        return {"url": self.url, "listeners": len(self._listeners), "token_file": self.token_file,
                "connections": len(server.connections) if server is not None else 0,
                "connections_refused": self.connections_refused, "streams": self.streams.open,
                "streams_refused": self.streams.refused, "streams_yielded": self.streams.yielded}


PUBLISHER = WebServer
