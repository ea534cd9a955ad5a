"""pymodbus 3.16's server as the appliance needs it on the wire: one unit id served (another unit's request is
ignored or answered as missing), function 5 as the specification has it, pipelined requests all answered,
and on TCP a connection cap, an idle time-out and an allow-list of client networks."""

from __future__ import annotations

import collections
import ipaddress
import logging
import struct
import time
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.pdu import ExceptionResponse
from pymodbus.pdu.bit_message import WriteSingleCoilRequest, WriteSingleCoilResponse
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator.simcore import SimCore

from .settings import _THIS_MACHINE, allowed_networks

log = logging.getLogger("moi.modbus")


class OneUnitCore(SimCore):
    """SimCore that treats an unknown unit id as missing instead of raising KeyError.

    pymodbus 3.16's SimCore falls back to device id 0 and raises KeyError when it
    is absent, which the request handler turns into a logged "device failure"
    reply; a request for another unit must instead be ignored (RTU, shared line)
    or answered with "gateway target failed to respond" (TCP).
    """

    async def async_getValues(self, device_id: int, func_code: int, address: int, count: int = 1):
        if device_id not in self.devices:
            raise NoSuchIdException(f"unit id {device_id} is not served")
        return await super().async_getValues(device_id, func_code, address, count)

    async def async_setValues(self, device_id: int, func_code: int, address: int, values):
        self.require_device(device_id)
        return await super().async_setValues(device_id, func_code, address, values)

    def require_device(self, device_id: int) -> None:
        if device_id not in self.devices:
            raise NoSuchIdException(f"unit id {device_id} is not served")


class WriteSingleCoil(WriteSingleCoilRequest):
    """Function 5 as the Modbus Application Protocol specification has it (section 6.5): the value
    is 0xFF00 or 0x0000, anything else is exception 03 (ILLEGAL DATA VALUE); the normal
    response is an echo of the request. pymodbus 3.16 reads any non-zero value as "on" and
    answers with the coil's read-back value."""

    value = 0x0000  # the value field as received

    def decode(self, data: bytes) -> None:
        self.address, self.value = struct.unpack(">HH", data[:4])
        self.bits = [self.value == 0xFF00]

    async def datastore_update(self, context, device_id: int):
        if isinstance(context, OneUnitCore):
            context.require_device(device_id)  # another unit's request is not ours to refuse
        if self.value not in (0x0000, 0xFF00):
            return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_VALUE)
        echo = list(self.bits)  # the access hook clears the written values (pulse coils)
        response = await super().datastore_update(context, device_id)
        if isinstance(response, WriteSingleCoilResponse):
            response.bits = echo
        return response


def _is_allowed(peer: str, networks: tuple) -> bool:
    try:
        addr = ipaddress.ip_address(peer.split("%", 1)[0])
    except ValueError:
        return False
    if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
        addr = addr.ipv4_mapped
    return any(addr in net for net in _THIS_MACHINE + networks)


class TrackedHandler(ServerRequestHandler):
    """A client connection that remembers when it last sent something (monotonic s)."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.last_activity = time.monotonic()
        self._requests: collections.deque = collections.deque()

    def connection_made(self, transport: Any) -> None:
        super().connection_made(transport)
        if self.is_closing:
            # closed for the cap between its accept and now (asyncio makes connections one loop turn after
            # accepting them): pymodbus had no transport to close then, so the socket would stay open
            transport.close()
            self.transport = None  # type: ignore[assignment]  # pymodbus types it without None; it means "closed"
            return
        server = self.server
        if not isinstance(server, BoundedTcpServer):
            return
        if server.allowed is not None:
            peer = (transport.get_extra_info("peername") or ("",))[0]
            if not _is_allowed(str(peer), server.allowed):
                server.refuse(self, str(peer))  # before the cap: a refused client never displaces an allowed one
                return
        server.make_room(self)

    def callback_data(self, data: bytes, addr: tuple | None = None) -> int:
        """Every complete request in ``data``: a client may send several in one segment (pipelining, as
        Modbus/TCP allows), and pymodbus reads one and leaves the others until more bytes come."""
        self.last_activity = time.monotonic()
        used = 0
        while used < len(data):
            n = super().callback_data(data[used:], addr)  # one request; its answer is scheduled
            if n <= 0:
                break  # an incomplete request: the transport keeps it for the next bytes
            used += n
            if self.last_pdu is not None:  # None: answered already (malformed) or not for this unit
                self._requests.append((self.last_pdu, self.last_addr))
        return used

    def send(self, data: bytes, addr: tuple | None = None) -> None:
        # pymodbus empties its receive buffer when it answers: a request already received in part would be lost
        kept = self.recv_buffer
        super().send(data, addr)
        self.recv_buffer = kept

    async def handle_request(self) -> None:
        # one scheduled answer per request read above, in order
        if not self._requests:
            return
        self.last_pdu, self.last_addr = self._requests.popleft()
        await super().handle_request()


class BoundedTcpServer(ModbusTcpServer):
    """ModbusTcpServer with a connection cap and an idle time-out: without them a client that
    opens connections and never closes them runs the process out of file descriptors (no new
    PLC connection, no MQTT reconnect). Beyond ``max_connections`` the connection idle the
    longest is closed to make room, so a PLC reconnecting always gets in."""

    def __init__(self, *args: Any, max_connections: int, idle_timeout: float, allow_from: tuple[str, ...] = (),
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.max_connections = max(1, max_connections)
        self.idle_timeout = idle_timeout
        self.dropped = 0  # connections closed for the cap or the idle time-out
        self.refused = 0  # connections from addresses outside allow_from
        self._last_warning = -float("inf")
        self._last_refusal_log = -float("inf")
        self.allowed = allowed_networks(allow_from) if allow_from else None

    def refuse(self, conn: Any, peer: str) -> None:
        self.refused += 1
        now = time.monotonic()
        if now - self._last_refusal_log >= 10.0:
            self._last_refusal_log = now
            log.warning("Modbus: refused a connection from %s (not in allow_from; %d refused so far)", peer,
                        self.refused)
        conn.close()

    def callback_new_connection(self) -> TrackedHandler:
        return TrackedHandler(self, self.trace_packet, self.trace_pdu, self.trace_connect)

    def make_room(self, new: Any) -> None:
        """Close the connections idle the longest until ``new`` fits under the cap."""
        others = [c for c in self.active_connections.values() if c is not new]
        while len(others) >= self.max_connections:
            oldest = min(others, key=lambda c: getattr(c, "last_activity", 0.0))
            others.remove(oldest)
            self._drop(oldest, f"more than {self.max_connections} connections")

    def close_idle(self) -> None:
        if self.idle_timeout <= 0:
            return
        now = time.monotonic()
        for conn in list(self.active_connections.values()):
            if now - getattr(conn, "last_activity", now) > self.idle_timeout:
                self._drop(conn, f"idle for more than {self.idle_timeout:g} s")

    def _drop(self, conn: Any, why: str) -> None:
        self.dropped += 1
        now = time.monotonic()
        if now - self._last_warning >= 10.0:  # one line per 10 s, however hard a client tries
            self._last_warning = now
            log.warning("Modbus: closed a client connection (%s; %d closed so far)", why, self.dropped)
        conn.close()
