"""What an OPC UA peer may cost the appliance, before and after it logs in.

asyncua's own limits where it has them: the transport's chunk and message sizes and chunk count
(``Server.limits``), the connections it accepts and how long one may stay without an activated session,
subscriptions. A guard in front where it has none:

* a chunk is refused on its 8-byte header: asyncua buffers the body a header announces (4 GB of zeros took a
  core for 30 s and hundreds of MB before its own size check ran on the whole body);
* at the connection cap, the oldest connection without a session makes room (asyncua refuses the newcomer:
  parked sockets would lock the real client out);
* one host opens at most ``NEW_PER_SECOND`` connections a second (a burst of ``NEW_BURST``): one more is
  closed before asyncua makes anything for it (a loop of connections each sending a hostile header cost the
  server's thread more than the header check saves);
* requests name at most ``max_nodes_per_request`` nodes (Read, Write, Browse, Call, monitored items...);
* wrong logins: each later message of that peer host before a session is activated waits ``GUESS_DELAY``,
  one at a time for the whole server; ``LOCKOUT_AFTER`` wrong ones within ``LOCKOUT_WINDOW`` throttle the
  host for ``LOCKOUT_SECONDS``: its messages before a login wait ``THROTTLE_DELAY`` each, one at a time for
  that host. Its logins are still tried: a client there with the right password gets in (a lockout refused it
  along with the guesser beside it), a guesser gets one try per ``THROTTLE_DELAY`` at most; said in the log
  with the peer's address, once a minute at most;
* while the sensor is read, requests are served one at a time and in at most ``CAPTURE_SHARE`` of the
  server thread's time (the web page's rule): a client is slowed, never refused.
"""

from __future__ import annotations

import asyncio
import logging
import math
import socket
import time
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, Callable

from asyncua import Server, ua
from asyncua.common.connection import TransportLimits
from asyncua.common.utils import ServiceError
from asyncua.crypto import uacrypto
from asyncua.server.binary_server_asyncio import BinaryServer, OPCUAProtocol

from service.publish.lockout import MOST_KEYS, Lockouts

log = logging.getLogger("moi.opcua")

#: the largest chunk a peer may send, bytes (asyncua's default receive buffer, and the specification's least)
MAX_CHUNK = 65535
#: the largest message, bytes: a result with its structures is a few kB; a browse of the whole space < 1 MB
MAX_MESSAGE = 4 * 1024 * 1024
#: each wrong login makes the peer's next message before a login wait this long, one at a time for the
#: whole server, s (the web page's token costs the same)
GUESS_DELAY = 0.5
#: this many wrong logins from one host within LOCKOUT_WINDOW throttle it for LOCKOUT_SECONDS
LOCKOUT_AFTER, LOCKOUT_WINDOW, LOCKOUT_SECONDS = 10, 60.0, 300.0
#: a throttled host's messages before a login each wait this long, one at a time for that host, s; at most
#: an eighth of the login timeout, so that a client's few messages up to its login fit in it
THROTTLE_DELAY = 2.0
#: at most one line per this many seconds for each kind of refusal, s
LOG_INTERVAL = 60.0
#: new connections a host may open per second, and at once
NEW_PER_SECOND, NEW_BURST = 10.0, 40
#: while the sensor is read, the share of the OPC UA thread's time requests may take at most
CAPTURE_SHARE = 0.1
#: a request's pause after it while the sensor is read, s, at most
MAX_PAUSE = 2.0

#: the peer address of the connection whose messages are being processed (each connection's task has its own)
PEER: ContextVar[str] = ContextVar("moi_opcua_peer", default="?")

#: the requests that name nodes, and where their list is (asyncua's InternalSession method → parameter field)
_LISTS: dict[str, str | None] = {
    "read": "NodesToRead", "write": "NodesToWrite", "browse": "NodesToBrowse", "history_read": "NodesToRead",
    "register_nodes": None, "translate_browsepaths_to_nodeids": None, "call": None,
    "create_monitored_items": "ItemsToCreate", "modify_monitored_items": "ItemsToModify",
}


@dataclass(frozen=True)
class Limits:
    """The guard's limits (``[opcua]``'s keys: ``OpcUaSettings``)."""

    max_connections: int = 16
    login_timeout: float = 30.0
    max_nodes_per_request: int = 1000
    max_subscriptions: int = 50


class _Refusals:
    """Counts of one kind of refusal, logged at most once per ``LOG_INTERVAL`` with the latest peer."""

    def __init__(self, what: str, clock: Callable[[], float]) -> None:
        self.what, self._clock = what, clock
        self.count, self._since, self._logged = 0, 0, -math.inf

    def __call__(self, peer: str, detail: str = "") -> None:
        self.count += 1
        self._since += 1
        now = self._clock()
        if now - self._logged >= LOG_INTERVAL:
            log.warning("OPC UA: %d %s since the last such line (the latest from %s%s)", self._since, self.what,
                        peer, f": {detail}" if detail else "")
            self._logged, self._since = now, 0


class Guard:
    """The appliance's limits on the OPC UA server: ``install(server)`` before ``server.start()``."""

    def __init__(self, limits: Limits, capturing: Callable[[], bool] = lambda: False,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.limits = limits
        self.capturing = capturing
        self._clock = clock
        self.logins: Lockouts[str] = Lockouts(LOCKOUT_AFTER, LOCKOUT_WINDOW, LOCKOUT_SECONDS, clock)  # by host
        self._guessing: asyncio.Lock | None = None
        self._throttles: dict[str, asyncio.Lock] = {}  # throttled host → its line
        self._gate: asyncio.Lock | None = None
        self.oversized = _Refusals("oversized chunk(s) refused", clock)
        self.evicted = _Refusals("connection(s) without a session closed to make room", clock)
        self.too_many = _Refusals("request(s) naming too many nodes refused", clock)
        self.wrong_logins = _Refusals("wrong login(s)", clock)
        self.throttled = _Refusals("message(s) before a login throttled: their host gave too many wrong logins",
                                   clock)
        self.gated = 0  # requests served through the capture's gate
        self._buckets: dict[str, list[float]] = {}  # host → [tokens, when counted]
        self.too_fast = _Refusals("connection(s) closed: their host opened them too fast", clock)
        self.delayed = 0  # messages before a login that waited for their host's wrong logins
        self.connected_in_capture = 0  # connections opened while the sensor was read (each costs the server's thread)

    def install(self, server: Server) -> None:
        lim = self.limits
        server.limits = TransportLimits(max_recv_buffer=MAX_CHUNK, max_send_buffer=MAX_CHUNK,
                                        max_chunk_count=math.ceil(MAX_MESSAGE / MAX_CHUNK),
                                        max_message_size=MAX_MESSAGE)
        iserver = server.iserver
        iserver.max_connections = lim.max_connections
        iserver.max_pending_activation_seconds = lim.login_timeout
        iserver.max_subscriptions = lim.max_subscriptions
        make_session = iserver.create_session

        def create_session(*args: Any, **kwargs: Any) -> Any:
            session = make_session(*args, **kwargs)
            for method, field in _LISTS.items():
                if hasattr(session, method):
                    setattr(session, method, self._bounded(getattr(session, method), field))
            return session

        iserver.create_session = create_session  # type: ignore[method-assign]

    def binary_server(self, server: Server) -> BinaryServer:
        """asyncua's binary server with this guard's protocol (``GuardedServer.start``)."""
        guard = self

        class _Binary(BinaryServer):
            def _make_protocol(self) -> OPCUAProtocol:
                return _Protocol(guard, iserver=self.iserver, policies=self._policies, clients=self.clients,
                                 closing_tasks=self.closing_tasks, limits=self.limits)

        ip, port = server._get_bind_socket_info()
        return _Binary(server.iserver, ip, port, server.limits)  # type: ignore[arg-type]

    def admit(self, host: str) -> bool:
        """Whether ``host`` may open one more connection now (a token bucket per host)."""
        now = self._clock()
        tokens, then = self._buckets.pop(host, (float(NEW_BURST), now))
        tokens = min(float(NEW_BURST), tokens + (now - then) * NEW_PER_SECOND)
        ok = tokens >= 1.0
        self._buckets[host] = [tokens - 1.0 if ok else tokens, now]  # newest last: the oldest go first
        while len(self._buckets) > 1024:
            self._buckets.pop(next(iter(self._buckets)))
        if not ok:
            self.too_fast(host)
        return ok

    # --- nodes per request ------------------------------------------------------------------------------------
    def _bounded(self, method: Callable[..., Any], field: str | None) -> Callable[..., Any]:
        limit = self.limits.max_nodes_per_request

        async def bounded(params: Any, *args: Any, **kwargs: Any) -> Any:
            items = params if field is None else getattr(params, field, None)
            if isinstance(items, list) and len(items) > limit:
                self.too_many(PEER.get(), f"{len(items)} > {limit}")
                raise ServiceError(ua.StatusCodes.BadTooManyOperations)
            return await method(params, *args, **kwargs)

        return bounded

    # --- logins -----------------------------------------------------------------------------------------------
    def login_failed(self, host: str) -> None:
        self.wrong_logins(host)
        if self.logins.failed(host):
            log.warning("OPC UA: %s throttled for %.0f s after %d wrong logins within %.0f s (a message before a "
                        "login every %.1f s; the right password still gets in)", host, LOCKOUT_SECONDS,
                        LOCKOUT_AFTER, LOCKOUT_WINDOW, self.throttle_delay())

    def throttle_delay(self) -> float:
        return min(THROTTLE_DELAY, self.limits.login_timeout / 8)

    async def before_login(self, host: str) -> None:
        """A message of a connection without an activated session: it waits if its host guessed wrong lately,
        in its host's line when the host is throttled."""
        if self.logins.locked_for(host) > 0:
            if host not in self._throttles and len(self._throttles) >= MOST_KEYS:  # hosts that never came back
                for h in [h for h, line in self._throttles.items() if not line.locked()]:
                    del self._throttles[h]
            line = self._throttles.setdefault(host, asyncio.Lock())
            async with line:
                self.throttled(host)
                await asyncio.sleep(self.throttle_delay())
            return
        if (waiting := self._throttles.get(host)) is not None and not waiting.locked():
            del self._throttles[host]
        if not self.logins.recent(host):
            return
        if self._guessing is None:
            self._guessing = asyncio.Lock()
        async with self._guessing:
            self.delayed += 1
            await asyncio.sleep(GUESS_DELAY)

    # --- the capture first ------------------------------------------------------------------------------------
    async def serve(self, process: Callable[[], Any]) -> Any:
        if not self.capturing():
            return await process()
        if self._gate is None:
            self._gate = asyncio.Lock()
        async with self._gate:
            self.gated += 1
            spent = time.thread_time()
            try:
                return await process()
            finally:
                spent = time.thread_time() - spent
                await asyncio.sleep(min(MAX_PAUSE, spent * (1.0 / CAPTURE_SHARE - 1.0)))

    def health(self) -> dict[str, int]:
        return {"oversized_chunks": self.oversized.count, "evicted_connections": self.evicted.count,
                "too_many_nodes": self.too_many.count, "wrong_logins": self.wrong_logins.count,
                "throttled": self.throttled.count, "too_fast": self.too_fast.count, "delayed_before_login": self.delayed,
                "gated_requests": self.gated}


def host_of(peer: Any) -> str:
    return str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)


class _Protocol(OPCUAProtocol):
    """asyncua's connection, behind the guard."""

    def __init__(self, guard: Guard, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.guard = guard
        self.opened = time.monotonic()

    def connection_made(self, transport: Any) -> None:
        PEER.set(host_of(transport.get_extra_info("peername")))  # the task made below inherits it
        if self.guard.capturing():
            self.guard.connected_in_capture += 1
        if not self.guard.admit(PEER.get()):
            self.peer_name = transport.get_extra_info("peername")
            transport.close()  # nothing of asyncua's is made for it
            return
        if len(self.clients) >= self.iserver.max_connections:
            waiting = [c for c in self.clients if not _activated(c)]
            if waiting:
                oldest = min(waiting, key=lambda c: getattr(c, "opened", 0.0))
                self.clients.remove(oldest)
                if oldest.transport is not None:
                    oldest.transport.close()
                self.guard.evicted(PEER.get())
        super().connection_made(transport)

    def data_received(self, data: bytes) -> None:
        if self.transport is None or self.transport.is_closing():
            return
        super().data_received(data)
        # what is left is the start of a chunk asyncua waits to complete: its header says how long it will be
        if len(self._buffer) >= 8 and (size := int.from_bytes(self._buffer[4:8], "little")) > MAX_CHUNK:
            self.guard.oversized(host_of(self.peer_name), f"{size} bytes announced")
            self._buffer = b""
            self.transport.close()

    async def _process_one_msg(self, header: Any, buf: Any) -> bool:
        if not _activated(self):
            await self.guard.before_login(PEER.get())
        return bool(await self.guard.serve(lambda: super(_Protocol, self)._process_one_msg(header, buf)))


def _activated(client: Any) -> bool:
    processor = getattr(client, "processor", None)
    session = getattr(processor, "session", None)
    return session is not None and session.is_activated()


class GuardedServer(Server):
    """asyncua's server with the guard in front of its connections."""

    def __init__(self, guard: Guard, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.guard = guard

    async def init(self, shelf_file: Any = None) -> None:
        await super().init(shelf_file)
        self.guard.install(self)

    async def start(self) -> None:
        # asyncua's Server.start with the guarded binary server in place of its own
        if self.iserver.certificate is not None:
            uacrypto.check_certificate(self.iserver.certificate, self._application_uri, socket.gethostname())
        await self._setup_server_nodes()
        await self.iserver.start()
        try:
            self.bserver = self.guard.binary_server(self)
            self.bserver.set_policies(self._policies)
            await self.bserver.start()
        except Exception:
            await self.iserver.stop()
            raise
