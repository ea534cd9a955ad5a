"""The Modbus server the PLC polls (pymodbus 3.16, TCP or RTU).

The register layout lives in ``service.registers``; this module serves it.
The server runs on its own asyncio loop in a thread (``drivers.aioloop.LoopThread``). The daemon hands it a new
result with ``publish_result`` and the live status with ``set_live``; both
build a complete register image and swap it in with one assignment, and every
request copies that image into pymodbus' datastore before pymodbus reads it,
so one request never mixes two images (see the snapshot protocol in
docs/modbus.md).

Writes: only the two command coils and the part ID / recipe_select holding
registers (``registers.WRITABLE``) are writable. The result image is declared
read-only (pymodbus answers 0x02), so is everything between it and the
writable block; coils other than the command coils are refused in the access
hook with 0x02. A single-coil write (function 5) must carry 0xFF00 (on) or
0x0000 (off), anything else is answered with exception 03 and fires nothing,
and its reply echoes the request (the coil itself reads back 0: the command
coils are pulses). A write to the part registers while a measurement runs (or
a trigger is about to start one) gets 0x06 (server device busy): the part
being measured cannot change; an unknown recipe number or a non-ASCII part ID
gets 0x03 (illegal data value).
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.framer import FramerType
from pymodbus.pdu import ExceptionResponse
from pymodbus.pdu.bit_message import WriteSingleCoilRequest, WriteSingleCoilResponse
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice
from pymodbus.simulator.simcore import SimCore

from drivers.aioloop import LoopThread

from . import registers as R
from .errors import ModbusServerError

log = logging.getLogger("moi.modbus")

_READ_REGISTERS = {3, 4}
_READ_DISCRETE = {2}
_WRITE_COILS = {5, 15}
_WRITE_REGISTERS = {6, 16}

#: after a trigger coil write, part writes are refused this long (s) until the daemon reports busy
TRIGGER_HOLD = 0.5


@dataclass(frozen=True)
class ModbusSettings:
    """Where and how to serve (see ``[modbus]`` in docs/service.md).

    mode: "tcp" | "rtu". host/port: TCP listen address (port 0: any free port).
    serial_port, baudrate, parity ("N"|"E"|"O"), stopbits, bytesize: RTU line
    (serial_port may be "socket://HOST:PORT" for a serial-over-TCP bridge).
    unit_id: the Modbus device id answered. word_order: "big" | "little".
    """

    mode: str = "tcp"
    host: str = "127.0.0.1"
    port: int = 5020
    unit_id: int = 1
    word_order: str = "big"
    serial_port: str | None = None
    baudrate: int = 19200
    parity: str = "E"
    stopbits: int = 1
    bytesize: int = 8


class _OneUnitCore(SimCore):
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


class _WriteSingleCoil(WriteSingleCoilRequest):
    """Function 5 as the Modbus Application Protocol specification has it (section 6.5): the value
    is 0xFF00 or 0x0000, anything else is exception 03 (ILLEGAL DATA VALUE); the normal
    response is an echo of the request. pymodbus 3.16 reads any non-zero value as "on" and
    answers with the coil's read-back value."""

    value = 0x0000  # the value field as received

    def decode(self, data: bytes) -> None:
        self.address, self.value = struct.unpack(">HH", data[:4])
        self.bits = [self.value == 0xFF00]

    async def datastore_update(self, context, device_id: int):
        if isinstance(context, _OneUnitCore):
            context.require_device(device_id)  # another unit's request is not ours to refuse
        if self.value not in (0x0000, 0xFF00):
            return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_VALUE)
        echo = list(self.bits)  # the access hook clears the written values (pulse coils)
        response = await super().datastore_update(context, device_id)
        if isinstance(response, WriteSingleCoilResponse):
            response.bits = echo
        return response


class ModbusServer:
    """Serves the register image of ``service.registers``.

    on_command(name, source, data) is called from the server thread when the PLC
    writes 1 to a command coil (name "trigger" or "abort"; called with two
    arguments), a part ID (name "part_id", data {"part_id": text}) or a recipe
    number ("recipe", {"recipe": number}); it must not block.
    ``recipe_numbers``: the recipe numbers the PLC may select (0 deselects).
    """

    def __init__(self, settings: ModbusSettings, on_command: Callable[..., None] | None = None,
                 recipe_numbers: frozenset[int] = frozenset()) -> None:
        if settings.word_order not in R.WORD_ORDERS:
            raise ValueError(f"word_order must be one of {R.WORD_ORDERS}")
        self.settings = settings
        self._on_command = on_command or (lambda name, source, data=None: None)
        self.recipe_numbers = recipe_numbers
        self._lock = threading.Lock()
        self._live = R.LiveStatus()
        self._snapshot = R.encode_snapshot(None, settings.word_order)
        self._verdict: str | None = None
        self._inputs = [0] * (R.WRITABLE_END - R.WRITABLE_START)  # the writable holding registers
        self._hold_until = 0.0  # monotonic time until which part writes are refused after a trigger
        self._result_valid = False
        self._image: tuple[int, ...] = ()
        self._status_bits = 0
        self._rebuild()
        self._io = LoopThread("moi-modbus")
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self.bound_port: int | None = None
        self.requests = 0  # requests served (all function codes), for diagnostics

    # --- data the daemon updates --------------------------------------------
    def publish_result(self, payload: Mapping[str, Any]) -> None:
        """Make a stored result the current snapshot (one atomic swap)."""
        words = R.encode_snapshot(payload, self.settings.word_order)
        with self._lock:
            self._snapshot = words
            self._verdict = payload.get("verdict")
            self._result_valid = True
            self._rebuild()

    def set_inputs(self, *, part_id: str | None = None, recipe: int | None = None) -> None:
        """Show a part ID / recipe set by another source (MQTT, config) in the writable registers."""
        with self._lock:
            if part_id is not None:
                a, n = R.WRITABLE["part_id"]
                self._inputs[a - R.WRITABLE_START: a - R.WRITABLE_START + n] = R.encode_ascii(part_id, 2 * n)
            if recipe is not None:
                self._inputs[R.WRITABLE["recipe_select"][0] - R.WRITABLE_START] = int(recipe) & 0xFFFF

    def inputs(self) -> dict[str, object]:
        """The writable registers as now: part_id (text) and recipe_select (number)."""
        a, n = R.WRITABLE["part_id"]
        words = self._inputs
        return {"part_id": R.decode_ascii(words[a - R.WRITABLE_START: a - R.WRITABLE_START + n]),
                "recipe_select": words[R.WRITABLE["recipe_select"][0] - R.WRITABLE_START]}

    def set_live(self, live: R.LiveStatus) -> None:
        if live.busy:
            self._hold_until = 0.0  # the daemon took the trigger: busy protects the part from here on
        with self._lock:
            if live != self._live:
                self._live = live
                self._rebuild()

    @property
    def live(self) -> R.LiveStatus:
        return self._live

    def image(self) -> tuple[int, ...]:
        """The registers 0 … IMAGE_SIZE-1 as served now."""
        return self._image

    def _rebuild(self) -> None:
        live = R.encode_live(self._live, self._result_valid, self.settings.word_order, self._verdict)
        # one assignment: a request handler sees the old or the new tuple, never a mix
        self._image = tuple(live + self._snapshot)
        self._status_bits = self._live.status_bits(self._result_valid, self._verdict)

    # --- pymodbus access hook (runs in the server's event loop) -------------------
    async def _action(self, func_code: int, start_address: int, address: int, count: int,
                      current: list, values: list | None) -> ExcCodes | None:
        self.requests += 1
        if func_code in _READ_REGISTERS:
            image = self._image
            current[0: len(image)] = image  # the block starts at address 0
            if func_code == 3:
                current[R.WRITABLE_START: R.WRITABLE_END] = self._inputs
            return None
        if func_code in _WRITE_REGISTERS and values is not None:
            return self._write_inputs(address, values)
        if func_code in _READ_DISCRETE:
            current[0] = self._status_bits
            return None
        if func_code in _WRITE_COILS and values is not None:
            if address < 0 or address + len(values) > len(R.COILS):
                return ExcCodes.ILLEGAL_ADDRESS
            names = {a: n for n, a in R.COILS.items()}
            for i, v in enumerate(values):
                if v:
                    name = names[address + i]
                    if name == "trigger":  # the part ID written before it is queued before it: it applies
                        self._hold_until = time.monotonic() + TRIGGER_HOLD
                    self._on_command(name, "modbus")
                values[i] = False  # command coils are pulses: they read back 0
            return None
        return None

    def _write_inputs(self, address: int, values: list) -> ExcCodes | None:
        """FC 6 / FC 16 to the part ID / recipe_select registers (pymodbus refused every other address)."""
        if address < R.WRITABLE_START or address + len(values) > R.WRITABLE_END:
            return ExcCodes.ILLEGAL_ADDRESS
        if self._live.busy or time.monotonic() < self._hold_until:
            return ExcCodes.DEVICE_BUSY  # the part being measured cannot change
        new = list(self._inputs)
        new[address - R.WRITABLE_START: address - R.WRITABLE_START + len(values)] = [int(v) & 0xFFFF for v in values]
        a, n = R.WRITABLE["part_id"]
        part_words = new[a - R.WRITABLE_START: a - R.WRITABLE_START + n]
        raw = b"".join(w.to_bytes(2, "big") for w in part_words).replace(b"\0", b"")
        if any(not 32 <= ch < 127 for ch in raw):
            return ExcCodes.ILLEGAL_VALUE
        recipe = new[R.WRITABLE["recipe_select"][0] - R.WRITABLE_START]
        touched = range(address, address + len(values))
        recipe_written = R.WRITABLE["recipe_select"][0] in touched
        if recipe_written and recipe != 0 and recipe not in self.recipe_numbers:
            return ExcCodes.ILLEGAL_VALUE
        self._inputs = new
        if any(a <= t < a + n for t in touched):
            self._on_command("part_id", "modbus", {"part_id": R.decode_ascii(part_words)})
        if recipe_written:
            self._on_command("recipe", "modbus", {"recipe": recipe})
        return None

    def _device(self) -> SimDevice:
        n_coil_regs = len(R.COILS)
        return SimDevice(
            id=self.settings.unit_id,
            simdata=(
                [SimData(0, count=n_coil_regs, values=False, datatype=DataType.BITS)],
                [SimData(0, count=len(R.STATUS_BITS), values=False, datatype=DataType.BITS)],
                [SimData(0, count=R.IMAGE_SIZE, values=0, datatype=DataType.REGISTERS, readonly=True),
                 SimData(R.WRITABLE_START, count=R.WRITABLE_END - R.WRITABLE_START, values=0,
                         datatype=DataType.REGISTERS)],
                [SimData(0, count=R.IMAGE_SIZE, values=0, datatype=DataType.REGISTERS, readonly=True)],
            ),
            action=self._action,
        )

    # --- lifecycle -------------------------------------------------------------------
    def start(self, timeout: float = 10.0) -> None:
        """Start serving; returns once the port is bound. Raises ModbusServerError if it cannot."""
        if self._io.running:
            raise RuntimeError("Modbus server already started")
        self._io.start()
        try:
            self._io.call(self._main(), timeout)
        except TimeoutError:
            self._io.stop()
            raise ModbusServerError(f"Modbus server did not start within {timeout} s") from None
        except BaseException as exc:
            self._io.stop()
            raise ModbusServerError(str(exc)) from None

    async def _main(self) -> None:
        s = self.settings
        device = self._device()
        if s.mode == "tcp":
            server = ModbusTcpServer(device, address=(s.host, s.port), ignore_missing_devices=False,
                                     custom_pdu=[_WriteSingleCoil])
            where = f"TCP {s.host}:{s.port}"
        elif s.mode == "rtu":
            server = ModbusSerialServer(device, framer=FramerType.RTU, port=s.serial_port or "", baudrate=s.baudrate,
                                        parity=s.parity, stopbits=s.stopbits, bytesize=s.bytesize,
                                        ignore_missing_devices=True, custom_pdu=[_WriteSingleCoil])
            where = f"RTU {s.serial_port} {s.baudrate} {s.bytesize}{s.parity}{s.stopbits}"
        else:
            raise ModbusServerError(f"unknown Modbus mode {s.mode!r}; expected tcp or rtu")
        server.context = _OneUnitCore(device)
        self._server = server
        try:
            await server.serve_forever(background=True)
        except RuntimeError:
            raise ModbusServerError(f"cannot listen on Modbus {where} (address in use, or no permission)") from None
        sockets = getattr(server.transport, "sockets", None)
        if sockets:
            self.bound_port = sockets[0].getsockname()[1]
        log.info("Modbus server on %s (unit id %d)", where if self.bound_port is None else
                 f"TCP {s.host}:{self.bound_port}", s.unit_id)

    def client_count(self) -> int | None:
        """Modbus TCP clients connected now (None for RTU or before the start)."""
        server = self._server if self.settings.mode == "tcp" else None
        conns = getattr(server, "active_connections", None)
        return len(conns) if conns is not None else None

    def alive(self) -> bool:
        """True while the server serves (after a successful ``start``)."""
        return self._io.running and self._server is not None and not self._server.serving.done()

    def stop(self, timeout: float = 5.0) -> None:
        if not self._io.running:
            return
        if self._server is not None:
            try:
                self._io.call(self._server.shutdown(), timeout)
            except Exception as exc:  # shutting down: nothing else to do but say so
                log.warning("Modbus server shutdown: %s", exc)
        self._io.stop(timeout)

    def __enter__(self) -> "ModbusServer":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
