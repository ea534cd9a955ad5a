"""The Modbus server the PLC polls (pymodbus 3.16, TCP or RTU).

The register layout lives in ``service.publish.modbus.registers``; this module serves it.
The server runs on its own asyncio loop in a thread (``drivers.aioloop.LoopThread``). The daemon hands it a new
result with ``publish_result`` and the live status with ``set_live``; both
build a complete register image and swap it in with one assignment, and every
request copies that image into pymodbus' datastore before pymodbus reads it,
so one request never mixes two images (see the snapshot protocol in
docs/modbus.md).

The PLC handshake (docs/modbus.md): a status word, an error code, a heartbeat
the main loop advances (``set_live``), a watchdog on the PLC's heartbeat, the
command register whose outcome the daemon reports through a reply
(``service.publish.replies``), and with ``result_handshake = "ack"`` a queue of
results the PLC acknowledges one by one (``result_ack``).

Writes: only the command coils and the holding registers of ``registers.WRITABLE``
are writable. The result image is declared
read-only (pymodbus answers 0x02), so is everything between it and the
writable block; coils other than the command coils are refused in the access
hook with 0x02. A single-coil write (function 5) must carry 0xFF00 (on) or
0x0000 (off), anything else is answered with exception 03 and fires nothing,
and its reply echoes the request (the coil itself reads back 0: the command
coils are pulses). A write to the part registers while a measurement runs (or
a trigger is about to start one) gets 0x06 (server device busy): the part
being measured cannot change; an unknown recipe number or a non-ASCII part ID
gets 0x03 (illegal data value), so do an unknown command code and an
acknowledgement of a `seq` that is not the one shown. A refused write changes
nothing. Function 22 (mask write) and 23 (read/write
multiple registers) get 0x01 (illegal function): a write is applied as the
functions above do, or refused, never acknowledged and dropped.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import threading
import time
from pathlib import Path
from typing import Any, Callable, Mapping

from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.aioloop import LoopThread
from service.core import vocabulary as V
from service.core.live import LiveStatus
from service.errors import ModbusServerError
from service.persistence.acks import AckFile, AckState
from service.publish.payload import not_decidable
from service.publish.port import ApplianceView, Publisher
from service.publish.replies import CommandReply

from . import registers as R

# the settings are read by the configuration without pymodbus; here for the server's users too
from .settings import ModbusSettings, network_exposure
from .transport import BoundedTcpServer, OneUnitCore, WriteSingleCoil

log = logging.getLogger("moi.modbus")

_READ_REGISTERS = {3, 4}
_READ_DISCRETE = {2}
_READ_COILS = {1}
_WRITE_COILS = {5, 15}
_WRITE_REGISTERS = {6, 16}

#: mode "ack": the file in the state directory that keeps what the PLC acknowledged (``service.persistence.acks``)
ACKED_FILE = "modbus-acked-seq"

#: after a trigger coil write, part writes are refused this long (s) until the daemon reports busy
TRIGGER_HOLD = 0.5


class _InputWrite:
    """One write to the writable holding registers: the registers it touches, and the block before it and as
    it would be after it."""

    def __init__(self, address: int, values: list, inputs: list[int]) -> None:
        self.touched = set(range(address, address + len(values)))
        self.old = inputs
        self.new = list(inputs)
        self.new[address - R.WRITABLE_START: address - R.WRITABLE_START + len(values)] = [int(v) & 0xFFFF
                                                                                           for v in values]

    def written(self, name: str) -> bool:
        a, n = R.WRITABLE[name]
        return bool(self.touched & set(range(a, a + n)))

    def word(self, name: str) -> int:
        return self.new[R.WRITABLE[name][0] - R.WRITABLE_START]

    def old_word(self, name: str) -> int:
        return self.old[R.WRITABLE[name][0] - R.WRITABLE_START]

    def part_words(self) -> list[int]:
        a, n = R.WRITABLE["part_id"]
        return self.new[a - R.WRITABLE_START: a - R.WRITABLE_START + n]


class ModbusServer(Publisher):
    """Serves the register image of ``service.publish.modbus.registers``.

    on_command(name, source, data) is called from the server thread when the PLC
    writes 1 to a command coil (name "trigger" or "abort"; called with two
    arguments), a part ID (name "part_id", data {"part_id": text}) or a recipe
    number ("recipe", {"recipe": number}); it must not block.
    ``recipe_numbers``: the recipe numbers the PLC may select (0 deselects). A command written to register
    `command` is handed on with a fourth argument, the reply that fills the command status registers.
    clock: monotonic s (the heartbeats and the hold after a trigger). acked_file: where mode "ack" keeps the
    sequence number of the last result the PLC acknowledged, so that a restart queues again the results
    stored since (``ModbusServer.build``).
    """

    def __init__(self, settings: ModbusSettings, on_command: Callable[..., None] | None = None,
                 recipe_numbers: frozenset[int] = frozenset(), clock: Callable[[], float] = time.monotonic,
                 acked_file: Path | None = None) -> None:
        if settings.word_order not in R.WORD_ORDERS:
            raise ValueError(f"word_order must be one of {R.WORD_ORDERS}")
        self.settings = settings
        self._on_command: Callable[..., None] = on_command or (lambda name, source, data=None, reply=None: None)
        self.recipe_numbers = recipe_numbers
        self._lock = threading.Lock()
        self._clock = clock
        self.acked_file = acked_file
        self._live = LiveStatus()
        self._snapshot = R.encode_snapshot(None, settings.word_order)
        self._verdict: str | None = None
        self._inputs = [0] * (R.WRITABLE_END - R.WRITABLE_START)  # the writable holding registers
        self._hold_until = 0.0  # monotonic time until which part writes are refused after a trigger
        self._result_valid = False
        self._shown: Mapping[str, Any] | None = None  # the payload the result block shows
        self._queue: collections.deque[tuple[int, list[int], Mapping[str, Any]]] = collections.deque()
        self.overrun_count = 0
        self._overrun = False  # a result found the queue full; cleared by acknowledge_fault
        self._heartbeat = 0
        self._heartbeat_tick = -1
        self._plc_heartbeat_at = clock()  # the last change of the PLC's heartbeat register
        self._plc_heartbeat_lost = False
        self._command = (0, 0, 0, 0)  # command_echo, command_status, command_reason, command_count
        self._trigger_ack = False
        self._image: tuple[int, ...] = ()
        self._tensor: tuple[int, ...] = tuple(R.encode_tensor(None, 0, settings.word_order))
        self._tensor_seq = 0
        self._status_bits = 0
        self._rebuild()
        self._io = LoopThread("moi-modbus")
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self._idle_task: asyncio.Task | None = None
        self.bound_port: int | None = None
        self.requests = 0  # requests served (all function codes), for diagnostics

    # --- data the daemon updates --------------------------------------------
    def publish_result(self, payload: Mapping[str, Any]) -> None:
        """A stored result: in mode "latest" it becomes the shown snapshot at once (one atomic swap); in mode
        "ack" it joins the queue and is shown when those before it are acknowledged (a full queue counts it in
        `overrun_count` and sets result_buffer_overrun instead)."""
        words = R.encode_snapshot(payload, self.settings.word_order)
        seq = R.modbus_seq(int(payload["seq"]))
        with self._lock:
            if self.settings.result_handshake == "ack":
                if len(self._queue) >= self.settings.queue_depth:
                    self.overrun_count += 1
                    self._overrun = True
                    log.warning("Modbus: result seq %d found %d results unacknowledged by the PLC: not queued "
                                "(%d so far; it is stored and sent over MQTT)", seq, len(self._queue),
                                self.overrun_count)
                    self._rebuild()
                    return
            else:
                self._queue.clear()
            self._queue.append((seq, words, payload))
            self._show()
            self._rebuild()

    def _show(self) -> None:
        """The oldest queued result becomes the snapshot (with the lock held); none queued: the last one stays,
        without ResultValid."""
        if self._queue:
            _, self._snapshot, self._shown = self._queue[0]
            self._verdict = self._shown.get("verdict")
        self._result_valid = bool(self._queue)

    def acknowledge(self, seq: int) -> bool:
        """The PLC acknowledged the shown result (its `seq`); False (nothing changes) when that is not the one
        shown or none is."""
        with self._lock:
            if not self._queue or self._queue[0][0] != seq:
                return False
            _, _, payload = self._queue.popleft()
            self._show()
            self._rebuild()
        if self.acked_file is not None:
            try:
                AckFile(self.acked_file).write(AckState(int(payload["seq"])))
            except OSError as exc:  # the acknowledgement holds; only a restart would queue the result again
                log.warning("Modbus: cannot keep the acknowledged position in %s: %s", self.acked_file, exc)
        return True

    def restore_queue(self, store: Any) -> None:
        """Mode "ack" after a restart: queue the results stored after the one the PLC acknowledged last (the
        newest ``queue_depth`` of them; older ones count as overrun). Without a kept position (the first
        start in this mode), the latest result is shown, as in mode "latest"."""
        kept = AckFile(self.acked_file).read() if self.acked_file is not None else None
        last = kept.through if kept is not None else None
        if last is None:
            latest = store.latest("ok")
            if latest is not None and latest.payload is not None:
                self.publish_result(latest.payload)
            return
        depth = self.settings.queue_depth
        rows = [r for r in store.list(limit=depth + 64, status="ok", full=True)
                if r.seq > last and r.payload is not None]
        rows.sort(key=lambda r: r.seq)
        for r in rows:
            self.publish_result(r.payload)

    def results_queued(self) -> int:
        return len(self._queue)

    def publish_tensor(self, tensor: Mapping[str, Any]) -> None:
        """Make a tensor set's result (``TensorResult.to_dict()``) the current tensor block (one atomic swap)."""
        with self._lock:
            self._tensor_seq += 1
            self._tensor = tuple(R.encode_tensor(tensor, self._tensor_seq, self.settings.word_order))

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

    def set_live(self, live: LiveStatus) -> None:
        """The live status (the daemon's main loop, every iteration): also advances the heartbeat and
        watches the PLC's."""
        if live.busy:
            self._hold_until = 0.0  # the daemon took the trigger: busy protects the part from here on
        now = self._clock()
        tick = int(now / R.HEARTBEAT_PERIOD)
        timeout = self.settings.plc_heartbeat_timeout
        with self._lock:
            changed = live != self._live
            if tick != self._heartbeat_tick:
                self._heartbeat_tick = tick
                self._heartbeat = (self._heartbeat + 1) & 0xFFFF
                changed = True
            lost = timeout > 0 and now - self._plc_heartbeat_at > timeout
            if lost != self._plc_heartbeat_lost:
                self._plc_heartbeat_lost = lost
                (log.warning if lost else log.info)(
                    "Modbus: the PLC's heartbeat (register %d) %s", R.WRITABLE["plc_heartbeat"][0],
                    f"did not change for {timeout:g} s" if lost else "changes again")
                changed = True
            if changed:
                self._live = live
                self._rebuild()

    @property
    def plc_heartbeat_lost(self) -> bool:
        return self._plc_heartbeat_lost

    @property
    def live(self) -> LiveStatus:
        return self._live

    def image(self) -> tuple[int, ...]:
        """The registers 0 … IMAGE_SIZE-1 as served now."""
        return self._image

    def _rebuild(self) -> None:
        live = R.encode_live(self._live, self._result_valid, self.settings.word_order, self._verdict)
        error = R.error_code(self._live, plc_heartbeat_lost=self._plc_heartbeat_lost, overrun=self._overrun)
        echo, status, reason, count = self._command
        handshake = R.Handshake(
            plc_status=R.plc_status_bits(
                ready=self._live.state == "IDLE" and not self._live.busy and not self._live.measure_refused,
                busy=self._live.busy,
                result_valid=self._result_valid, result_buffer_overrun=self._overrun, error=error != 0,
                calibration_due=self._live.calibration_due, not_decidable=not_decidable(self._shown),
                trigger_ack=self._trigger_ack, plc_heartbeat_lost=self._plc_heartbeat_lost),
            error_code=error, heartbeat=self._heartbeat, results_queued=len(self._queue),
            overrun_count=self.overrun_count, command_echo=echo, command_status=status, command_reason=reason,
            command_count=count)
        # one assignment: a request handler sees the old or the new tuple, never a mix
        self._image = R.assemble_image(live, self._snapshot, R.encode_handshake(handshake))
        self._status_bits = R.status_bits(self._live, self._result_valid, self._verdict)

    def _reply_to(self, code: int) -> Callable[[CommandReply], None]:
        """The reply of a command written to register `command` (the daemon's main loop calls it)."""

        def reply(r: CommandReply) -> None:
            with self._lock:
                count = (self._command[3] + 1) & 0xFFFF
                self._command = (code, R.COMMAND_STATUS[r.status], r.reason_code, count)
                if R.COMMANDS[code] == V.TRIGGER and r.status == "accepted":
                    self._trigger_ack = True
                elif R.COMMANDS[code] == V.TRIGGER:
                    self._hold_until = 0.0  # refused: no part is being measured, the PLC may change it at once
                if R.COMMANDS[code] == V.ACKNOWLEDGE_FAULT and r.status in ("done", "refused"):
                    self._overrun = False  # the overrun is acknowledged with the fault (its count stays)
                self._rebuild()

        return reply

    # --- pymodbus access hook (runs in the server's event loop) -------------------
    async def _action(self, func_code: int, start_address: int, address: int, count: int,
                      current: list, values: list | None) -> ExcCodes | None:
        self.requests += 1
        if func_code in _READ_REGISTERS:
            image = self._image
            current[0: len(image)] = image  # the block starts at address 0
            current[R.TENSOR_START: R.TENSOR_END] = self._tensor
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
                    if name == V.TRIGGER:  # the part ID written before it is queued before it: it applies
                        self._hold_until = self._clock() + TRIGGER_HOLD
                    self._on_command(name, "modbus")
                values[i] = False  # command coils are pulses: they read back 0
            return None
        if func_code in _READ_COILS or func_code in _WRITE_COILS or func_code in _WRITE_REGISTERS:
            return None  # the command coils read 0; the read-back of a write function
        # any other function that reaches the data (22 mask write, 23 read/write multiple registers) would
        # be answered as done and not applied: the PLC is told instead that it is not served
        return ExcCodes.ILLEGAL_FUNCTION

    def _write_inputs(self, address: int, values: list) -> ExcCodes | None:
        """FC 6 / FC 16 to the writable holding registers (pymodbus refused every other address). Everything
        written is checked first: a refused write changes nothing."""
        if address < R.WRITABLE_START or address + len(values) > R.WRITABLE_END:
            return ExcCodes.ILLEGAL_ADDRESS
        write = _InputWrite(address, values, self._inputs)
        refused = self._refusal(write)
        if refused is None:
            self._apply(write)
        return refused

    def _refusal(self, w: _InputWrite) -> ExcCodes | None:
        """Why the write is refused (the first check it fails, in the order docs/modbus.md gives), or None."""
        if any(w.written(n) for n in R.PART_INPUTS) and (self._live.busy or self._clock() < self._hold_until):
            return ExcCodes.DEVICE_BUSY  # the part being measured cannot change
        raw = b"".join(word.to_bytes(2, "big") for word in w.part_words()).replace(b"\0", b"")
        if any(not 32 <= ch < 127 for ch in raw):
            return ExcCodes.ILLEGAL_VALUE
        recipe = w.word("recipe_select")
        if w.written("recipe_select") and recipe != 0 and recipe not in self.recipe_numbers:
            return ExcCodes.ILLEGAL_VALUE
        command, parameter = w.word("command"), w.word("command_parameter")
        if w.written("command") and command != 0 and (command not in R.COMMANDS or (
                R.COMMANDS[command] == "select_recipe" and parameter != 0 and parameter not in self.recipe_numbers)):
            return ExcCodes.ILLEGAL_VALUE
        if w.written("result_ack"):
            with self._lock:
                if not self._queue or self._queue[0][0] != w.word("result_ack"):
                    return ExcCodes.ILLEGAL_VALUE  # not the result shown: nothing is acknowledged
        return None

    def _apply(self, w: _InputWrite) -> None:
        """A write that passed every check: the registers take it, and what it asks for is handed on."""
        if w.written("plc_heartbeat") and w.word("plc_heartbeat") != w.old_word("plc_heartbeat"):
            self._plc_heartbeat_at = self._clock()
        self._inputs = w.new
        if w.written("result_ack"):
            self.acknowledge(w.word("result_ack"))
        if w.written("part_id"):
            self._on_command(V.PART_ID, "modbus", {"part_id": R.decode_ascii(w.part_words())})
        if w.written("recipe_select"):
            self._on_command(V.RECIPE, "modbus", {"recipe": w.word("recipe_select")})
        if w.written("command"):
            with self._lock:
                self._trigger_ack = False  # the PLC took its hand off the trigger (or gives a new command)
                self._rebuild()
            if w.word("command") != 0:
                self._dispatch(w.word("command"), w.word("command_parameter"))

    def _dispatch(self, code: int, parameter: int) -> None:
        name = R.COMMANDS[code]
        reply = self._reply_to(code)
        if name == V.TRIGGER:
            self._hold_until = self._clock() + TRIGGER_HOLD
            self._on_command(V.TRIGGER, "modbus", None, reply)
        elif R.DAEMON_COMMAND.get(name) == V.RECIPE:
            self._on_command(V.RECIPE, "modbus", {"recipe": parameter}, reply)
        else:
            self._on_command(name, "modbus", None, reply)

    def _device(self) -> SimDevice:
        n_coil_regs = len(R.COILS)
        return SimDevice(
            id=self.settings.unit_id,
            simdata=(
                [SimData(0, count=n_coil_regs, values=False, datatype=DataType.BITS)],
                [SimData(0, count=len(R.STATUS_BITS), values=False, datatype=DataType.BITS)],
                [SimData(0, count=R.IMAGE_SIZE, values=0, datatype=DataType.REGISTERS, readonly=True),
                 SimData(R.WRITABLE_START, count=R.WRITABLE_END - R.WRITABLE_START, values=0,
                         datatype=DataType.REGISTERS),
                 SimData(R.TENSOR_START, count=R.TENSOR_END - R.TENSOR_START, values=0,
                         datatype=DataType.REGISTERS, readonly=True)],
                [SimData(0, count=R.IMAGE_SIZE, values=0, datatype=DataType.REGISTERS, readonly=True),
                 SimData(R.TENSOR_START, count=R.TENSOR_END - R.TENSOR_START, values=0,
                         datatype=DataType.REGISTERS, readonly=True)],
            ),
            action=self._action,
        )

    # --- lifecycle -------------------------------------------------------------------
    def start(self, timeout: float = 10.0) -> None:
        """Start serving; returns once the port is bound. Raises ModbusServerError if it cannot."""
        if self._io.running:
            raise RuntimeError("Modbus server already started")
        try:
            self._io.start_serving(self._main(), timeout)
        except TimeoutError:
            raise ModbusServerError(f"Modbus server did not start within {timeout} s") from None
        except Exception as exc:
            raise ModbusServerError(str(exc)) from None

    async def _main(self) -> None:
        s = self.settings
        device = self._device()
        server: BoundedTcpServer | ModbusSerialServer
        if s.mode == "tcp":
            server = BoundedTcpServer(device, address=(s.host, s.port), ignore_missing_devices=False,
                                       custom_pdu=[WriteSingleCoil], max_connections=s.max_connections,
                                       idle_timeout=s.idle_timeout, allow_from=tuple(s.allow_from))
            where = f"TCP {s.host}:{s.port}"
        elif s.mode == "rtu":
            server = ModbusSerialServer(device, framer=FramerType.RTU, port=s.serial_port or "", baudrate=s.baudrate,
                                        parity=s.parity, stopbits=s.stopbits, bytesize=s.bytesize,
                                        ignore_missing_devices=True, custom_pdu=[WriteSingleCoil])
            where = f"RTU {s.serial_port} {s.baudrate} {s.bytesize}{s.parity}{s.stopbits}"
        else:
            raise ModbusServerError(f"unknown Modbus mode {s.mode!r}; expected tcp or rtu")
        server.context = OneUnitCore(device)
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
        if (exposure := network_exposure(s)) is not None:
            log.warning("%s", exposure)
        if isinstance(server, BoundedTcpServer) and s.idle_timeout > 0:
            # a reference is kept: the loop holds tasks only weakly
            self._idle_task = asyncio.get_running_loop().create_task(self._close_idle(server, s.idle_timeout))

    @staticmethod
    async def _close_idle(server: "BoundedTcpServer", idle_timeout: float) -> None:
        while not server.serving.done():
            await asyncio.wait([server.serving], timeout=min(1.0, idle_timeout / 4))
            server.close_idle()

    def client_count(self) -> int | None:
        """Modbus TCP clients connected now (None for RTU or before the start)."""
        server = self._server if self.settings.mode == "tcp" else None
        conns = getattr(server, "active_connections", None)
        return len(conns) if conns is not None else None

    @property
    def connections_refused(self) -> int:
        """TCP connections refused since start (client address not in ``allow_from``)."""
        server = self._server
        return server.refused if isinstance(server, BoundedTcpServer) else 0

    @property
    def connections_dropped(self) -> int:
        """TCP client connections closed for the cap or the idle time-out since start."""
        server = self._server
        return server.dropped if isinstance(server, BoundedTcpServer) else 0

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

    # --- the publisher port ---------------------------------------------------------
    NAME = "modbus"
    EARLY = True  # the PLC sees STARTING, and the last result, while the devices open

    @classmethod
    def build(cls, settings: ModbusSettings, appliance: ApplianceView) -> "ModbusServer":
        parts, store = appliance.parts, appliance.store
        server = cls(settings, on_command=appliance.command, recipe_numbers=parts.book.numbers,
                     acked_file=Path(appliance.config.state_dir) / ACKED_FILE)
        server.set_inputs(recipe=parts.recipe.number if parts.recipe else 0)
        if store is not None:
            # until the main loop runs, the PLC sees STARTING and the true outbox backlog, not defaults
            server.set_live(LiveStatus(state="STARTING", simulated=appliance.config.simulated,
                                         outbox_pending=store.outbox_count()))
            if settings.result_handshake == "ack":
                server.restore_queue(store)  # the results the PLC has not acknowledged, again
            else:
                last = store.latest("ok")
                if last is not None and last.payload is not None:
                    server.publish_result(last.payload)  # the PLC sees the last result after a restart too
        return server

    def failure(self) -> str | None:
        return None if self.alive() else "the Modbus server thread stopped"

    def where(self) -> str:
        s = self.settings
        return f"Modbus {s.mode.upper()} " + (f"{s.host}:{self.bound_port}" if s.mode == "tcp" else str(s.serial_port))

    def health(self) -> dict[str, Any]:
        return {"mode": self.settings.mode, "port": self.bound_port, "clients": self.client_count(),
                "requests": self.requests, "result_handshake": self.settings.result_handshake,
                "results_queued": self.results_queued(), "overrun_count": self.overrun_count,
                "plc_heartbeat_lost": self._plc_heartbeat_lost}

    def status(self) -> list[str]:
        out = []
        if self._plc_heartbeat_lost:
            out.append(f"PLC heartbeat lost (no change for {self.settings.plc_heartbeat_timeout:g} s)")
        if self._overrun:
            out.append(f"{self.overrun_count} result(s) found the PLC's queue full")
        return out

    def on_live(self, live: LiveStatus) -> None:
        self.set_live(live)

    def on_result(self, stored: Any, measurement: Any) -> None:
        if stored.payload is not None:
            self.publish_result(stored.payload)

    def on_recipe(self, recipe: Any) -> None:
        self.set_inputs(recipe=recipe.number if recipe else 0)

    def on_part_id(self, part_id: str | None) -> None:
        self.set_inputs(part_id=part_id or "")

    def on_tensor_set(self, record: Mapping[str, Any]) -> None:
        if record.get("status") == "complete" and record.get("tensor") is not None:
            self.publish_tensor(record["tensor"])

    def __enter__(self) -> "ModbusServer":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


PUBLISHER = ModbusServer
