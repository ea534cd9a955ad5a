"""RS-485 Modbus RTU absolute encoder: the client that samples the pendulum angle.

``ModbusEncoder`` is an ``AngleSensor``: between ``start()`` and ``stop()`` it
reads the position register(s) back to back, as fast as the bus answers
(pymodbus ``AsyncModbusSerialClient`` on its own thread and event loop,
pyserial underneath: ``/dev/ttyUSB0`` on the device, ``socket://host:port``
for the simulated encoder). Each sample is timestamped on the host, on the
injected clock, at the midpoint between sending the request and receiving
the reply (the encoder latches somewhere in between; a constant bias does not
change J).

Failed reads are dropped (the trace keeps its gaps) and counted by kind:

    timeouts          no reply within ``timeout``
    crc_errors        a reply arrived but its CRC was wrong (the framer rejected it)
    exceptions        the encoder answered with a Modbus exception (e.g. 2: illegal
                      data address: wrong ``register`` or ``registers``)
    connection_errors the port could not be opened or the link dropped

A run of ``max_consecutive_errors`` failures in a row is an ``EncoderFault``
(raised by the next ``read()``): never a hang, never a silent empty trace.
"""

from __future__ import annotations

import asyncio
import logging
import math
import socket
import time
from collections import deque
from dataclasses import dataclass, fields
from enum import Enum
from typing import TYPE_CHECKING, Any

import numpy as np

from measurement.flags import ENCODER_ERRORS

from .aioloop import LoopThread
from .clock import Clock, MonotonicClock
from .errors import DriverConfigError, EncoderFault
from .modbus_words import WORD_ORDERS, from_registers
from .sensor import SampleBuffer

if TYPE_CHECKING:  # as a type only: pymodbus is imported where a client is made
    from pymodbus.client import AsyncModbusSerialClient

log = logging.getLogger("moi.drivers.encoder")

REGISTER_TYPES = ("holding", "input")
PARITIES = ("N", "E", "O")


class Failure(Enum):
    """Why one read of the position failed; the value is its counter in ``stats()``."""

    TIMEOUT = "timeouts"
    CRC = "crc_errors"
    EXCEPTION = "exceptions"
    CONNECTION = "connection_errors"


@dataclass(frozen=True)
class ReadFailure:
    """One failed read: its kind and what happened, in words."""

    kind: Failure
    detail: str


def check_register_layout(device_id: Any, register: Any, registers: Any, word_order: Any, counts_per_turn: Any,
                          direction: Any, *, what: str) -> None:
    """Validate the bus layout shared by the client and the simulated server (raises DriverConfigError)."""
    def is_int(v: Any) -> bool:
        return isinstance(v, int) and not isinstance(v, bool)

    if not (is_int(device_id) and 1 <= device_id <= 247):
        raise DriverConfigError(f"{what}: device_id must be a Modbus RTU address 1..247, got {device_id!r}")
    if not (is_int(register) and 0 <= register <= 65534):
        raise DriverConfigError(f"{what}: register must be an address 0..65534, got {register!r}")
    if registers not in (1, 2) or not is_int(registers):
        raise DriverConfigError(f"{what}: registers must be 1 (16-bit position) or 2 (32-bit), got {registers!r}")
    if word_order not in WORD_ORDERS:
        raise DriverConfigError(f"{what}: word_order must be 'big' (high word first) or 'little', got {word_order!r}")
    if not (is_int(counts_per_turn) and 16 <= counts_per_turn <= (1 << (16 * registers))):
        raise DriverConfigError(
            f"{what}: counts_per_turn must be an integer in 16..{1 << (16 * registers)} for {registers} register(s), "
            f"got {counts_per_turn!r}")
    if direction not in (1, -1) or not is_int(direction):
        raise DriverConfigError(f"{what}: direction must be 1 or -1, got {direction!r}")


@dataclass(frozen=True)
class EncoderConfig:
    """How to reach and read the encoder (the ``[encoder]`` table of the device settings).

    port: serial device ("/dev/ttyUSB0") or pyserial URL ("socket://127.0.0.1:5020").
    device_id: Modbus RTU address 1..247. baudrate: bit/s; parity "N"/"E"/"O"; stopbits 1|2.
    register: address of the (first) position register; register_type "holding" (function 3)
        or "input" (function 4); registers: 1 (16-bit) or 2 (32-bit position).
    word_order: "big" (high word first) or "little", for 2 registers.
    counts_per_turn: counts per revolution (2**17 for a 17-bit encoder).
    direction: +1, or −1 to flip the sign of the angle.
    zero: counts read at the rig's zero angle (hanging at rest).
    timeout: s to wait for one reply. max_consecutive_errors: this many failed reads in
        a row is an EncoderFault.
    min_interval: s between the starts of two requests (0: as fast as the bus allows).
    late_reply_factor: a reply whose round trip exceeds the recent short round trips (the 10th
        percentile of the last 256) by more than (late_reply_factor − 1) times the capture's
        shortest of them is dropped and counted in ``late_replies``: its host timestamp, the
        midpoint of request and reply, is uncertain by half the excess, an angle error of θ'·Δt.
        With the default 1.5 a kept sample's time is off by at most a quarter of the link's round
        trip, however busy the host. 0 keeps every reply.
    After a time-out the client waits another ``timeout`` for the line to go quiet before the next
    request; a reply arriving in that wait is ignored and counted in ``stale_replies`` (also
    counted in ``timeouts``): many of them mean the time-out is shorter than the device's answer.
    """

    port: str
    device_id: int = 1
    baudrate: int = 115200
    parity: str = "N"
    stopbits: int = 1
    bytesize: int = 8
    register: int = 0
    register_type: str = "holding"
    registers: int = 2
    word_order: str = "big"
    counts_per_turn: int = 1 << 17
    direction: int = 1
    zero: int = 0
    timeout: float = 0.05
    max_consecutive_errors: int = 10
    min_interval: float = 0.0
    late_reply_factor: float = 1.5

    def __post_init__(self) -> None:
        if not (isinstance(self.port, str) and self.port.strip()):
            raise DriverConfigError(f"encoder: port must be a serial device or socket:// URL, got {self.port!r}")
        check_register_layout(self.device_id, self.register, self.registers, self.word_order, self.counts_per_turn,
                              self.direction, what="encoder")
        if not (isinstance(self.baudrate, int) and 300 <= self.baudrate <= 4_000_000):
            raise DriverConfigError(f"encoder: baudrate must be an integer 300..4000000 bit/s, got {self.baudrate!r}")
        if self.parity not in PARITIES:
            raise DriverConfigError(f"encoder: parity must be one of N, E, O, got {self.parity!r}")
        if self.stopbits not in (1, 2):
            raise DriverConfigError(f"encoder: stopbits must be 1 or 2, got {self.stopbits!r}")
        if self.bytesize not in (7, 8):
            raise DriverConfigError(f"encoder: bytesize must be 7 or 8, got {self.bytesize!r}")
        if self.register_type not in REGISTER_TYPES:
            raise DriverConfigError(f"encoder: register_type must be 'holding' or 'input', got {self.register_type!r}")
        if not isinstance(self.zero, int) or isinstance(self.zero, bool):
            raise DriverConfigError(f"encoder: zero must be an integer count, got {self.zero!r}")
        if not (isinstance(self.timeout, (int, float)) and 0.001 <= self.timeout <= 10):
            raise DriverConfigError(f"encoder: timeout must be 0.001..10 s, got {self.timeout!r}")
        if not (isinstance(self.max_consecutive_errors, int) and self.max_consecutive_errors >= 1):
            raise DriverConfigError(
                f"encoder: max_consecutive_errors must be an integer >= 1, got {self.max_consecutive_errors!r}")
        if not (isinstance(self.min_interval, (int, float)) and 0 <= self.min_interval <= 1):
            raise DriverConfigError(f"encoder: min_interval must be 0..1 s, got {self.min_interval!r}")
        f = self.late_reply_factor
        if not (isinstance(f, (int, float)) and not isinstance(f, bool) and (f == 0 or 1.1 <= f <= 100)):
            raise DriverConfigError(f"encoder: late_reply_factor must be 0 (off) or 1.1..100 times the shortest "
                                    f"round trip, got {f!r}")

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "EncoderConfig":
        """From a TOML table; unknown keys are an error naming the known ones."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise DriverConfigError(f"encoder: unknown setting(s) {', '.join(unknown)}; expected some of {', '.join(sorted(known))}")
        if "port" not in d:
            raise DriverConfigError("encoder: 'port' is required (e.g. '/dev/ttyUSB0')")
        return cls(**d)

    def counts_to_angle(self, value: int) -> float:
        """Single-turn angle (rad, in (−π, π]) of a raw register value, relative to ``zero``."""
        half = self.counts_per_turn // 2
        d = (value - self.zero) % self.counts_per_turn
        if d > half:
            d -= self.counts_per_turn
        return self.direction * 2.0 * math.pi * d / self.counts_per_turn


def _crc16(frame: bytes) -> int:
    crc = 0xFFFF
    for byte in frame:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def bad_crc(frame: bytes) -> bool:
    """True when an RTU frame (>= 4 bytes) ends with a CRC that does not match its content."""
    if len(frame) < 4:
        return False
    return _crc16(frame[:-2]) != int.from_bytes(frame[-2:], "little")


def _send_immediately(client: Any) -> None:
    """Disable Nagle's algorithm on a socket:// port so each request leaves at once, as on a serial line.

    Without it a request sent after an unanswered one waits for the peer's
    delayed ACK (~40 ms) and times out as well, doubling every lost reply.
    pymodbus keeps the pyserial port at ``client.ctx.transport.sync_serial``.
    """
    port = getattr(getattr(getattr(client, "ctx", None), "transport", None), "sync_serial", None)
    if port is None:
        log.warning("cannot disable Nagle (pymodbus keeps no port at client.ctx.transport.sync_serial): "
                    "replies after a lost one may time out too")
        return
    try:
        fd = port.fileno()
        with socket.fromfd(fd, socket.AF_INET, socket.SOCK_STREAM) as sock:  # a dup: closing it keeps the port
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except (AttributeError, OSError) as exc:
        log.warning("cannot disable Nagle on %r (%s): replies after a lost one may time out too", port, exc)


class ModbusEncoder:
    """The Modbus RTU absolute encoder as an ``AngleSensor`` (source "encoder").

    config: ``EncoderConfig``; clock: the sequencer's clock (timestamps), a
    real-time one (MonotonicClock, or ScaledClock with the simulated encoder).

    The I/O runs on a private thread with its own event loop, started on the
    first ``start()``; ``read()`` only drains a buffer and never blocks.
    """

    source = "encoder"

    def __init__(self, config: EncoderConfig, clock: Clock | None = None):
        self.config = config
        self.clock = clock or MonotonicClock()
        self._buffer = SampleBuffer()
        self._lock = self._buffer.lock  # also guards the counters
        self._io = LoopThread("moi-encoder-io")
        self._client: AsyncModbusSerialClient | None = None
        self._task: asyncio.Task | None = None
        self._sampling = False
        self._closed = False
        self._rx = bytearray()  # bytes received for the request in flight (CRC check)
        self._counts = self._zero_counts()
        self._unwrap_last: float | None = None
        self._rtts: deque[float] = deque(maxlen=256)  # recent round trips, clock s
        self._rtt_floor = math.inf  # the capture's shortest reference round trip, clock s (see _late)

    # -- AngleSensor ---------------------------------------------------------------
    def start(self) -> None:
        """Start sampling (connects on the I/O thread; connection failures count toward a fault)."""
        if self._closed:
            raise EncoderFault("encoder fault: start() after close()")
        self._io.start()
        self._stop_task()
        with self._lock:
            self._buffer.reset()
            self._counts = self._zero_counts()
            self._unwrap_last = None
        self._io.call(self._begin_sampling())

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """Samples since the last read: (t in s on the clock, angle in rad). Raises EncoderFault after a fault."""
        return self._buffer.drain()

    def stop(self) -> None:
        """Stop sampling (keeps the port open for the next capture); samples already taken stay readable."""
        self._stop_task()

    def stats(self) -> dict:
        """Counters of the current/last capture: samples, requests and the failed reads by kind."""
        with self._lock:
            c = {"samples": self._buffer.count, **self._counts}
            rate = self._buffer.rate()
        c["errors"] = c["timeouts"] + c["crc_errors"] + c["exceptions"] + c["connection_errors"]
        c["port"] = self.config.port
        c["device_id"] = self.config.device_id
        if c["requests"]:
            c["error_rate"] = c["errors"] / c["requests"]
        if rate is not None:
            c["rate_hz"] = rate
        c.pop("consecutive_errors", None)
        return c

    def flags(self) -> tuple[str, ...]:
        return (ENCODER_ERRORS,) if self.stats()["errors"] else ()

    def wait_for_samples(self, n: int, timeout: float) -> bool:
        """Block until ``n`` samples were taken since ``start()`` (True), a fault, or ``timeout`` s of real time (False)."""
        return self._buffer.wait_for(n, timeout)

    def close(self) -> None:
        """Stop sampling, close the port and the I/O thread; safe twice."""
        if self._closed:
            return
        self._closed = True
        self._stop_task()
        if self._io.running:
            try:
                self._io.call(self._close_client(), 2.0)
            except Exception:  # closing a dead port: nothing more to do
                log.debug("encoder close raised", exc_info=True)
        self._io.stop(2.0)

    def __enter__(self) -> "ModbusEncoder":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- one-off read (diagnostics) -------------------------------------------------
    def read_position(self, timeout: float = 2.0) -> tuple[float, float]:
        """One read outside a capture: (t in s on the clock, single-turn angle in rad). Raises EncoderFault."""
        self._io.start()
        try:
            outcome = self._io.call(self._read_once(), timeout)
        except TimeoutError:
            raise EncoderFault(f"encoder fault: no answer from {self._where()} within {timeout:g} s") from None
        if isinstance(outcome, ReadFailure):
            raise EncoderFault(f"encoder fault: {self._where()}: {outcome.detail}")
        t, value, _ = outcome
        return t, self.config.counts_to_angle(value)

    # -- I/O thread -------------------------------------------------------------------
    @staticmethod
    def _zero_counts() -> dict[str, Any]:
        return {"requests": 0, "timeouts": 0, "crc_errors": 0, "exceptions": 0,
                "connection_errors": 0, "max_run_of_errors": 0, "consecutive_errors": 0,
                "rtt_max_s": 0.0, "late_replies": 0, "stale_replies": 0}

    def _snapshot(self) -> dict[str, Any]:
        """The counters as a fault carries them (call with the lock held)."""
        return {"samples": self._buffer.count, **self._counts}

    def _where(self) -> str:
        return f"device {self.config.device_id} on {self.config.port}"

    async def _begin_sampling(self) -> None:
        self._sampling = True
        self._task = asyncio.get_running_loop().create_task(self._guarded_sample_loop())

    async def _guarded_sample_loop(self) -> None:
        try:
            await self._sample_loop()
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # top of the I/O thread: an unforeseen client error must surface as a fault, not silence
            log.exception("encoder sampling stopped")
            with self._lock:
                self._buffer.fail(EncoderFault(f"encoder fault: sampling stopped on {self._where()}: "
                                               f"{type(exc).__name__}: {exc}", self._snapshot()))

    async def _end_sampling(self) -> None:
        # A flag, not only cancel(): on Python 3.11 asyncio.wait_for (inside pymodbus) swallows a
        # cancellation that races a reply, and the loop would keep reading. The flag ends it after
        # the read in flight (at most one time-out); cancel() is the fallback.
        task, self._task = self._task, None
        self._sampling = False
        if task is None or task.done():
            return
        await asyncio.wait({task}, timeout=self.config.timeout + 0.5)
        for _ in range(50):
            if task.done():
                break
            task.cancel()
            await asyncio.wait({task}, timeout=0.1)
        else:
            log.error("encoder sampling task did not stop")
        if task.done() and not task.cancelled() and task.exception() is not None:
            log.error("encoder sampling ended with %r", task.exception())

    def _stop_task(self) -> None:
        if self._task is None or not self._io.running:
            return
        self._io.call(self._end_sampling())

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            self._rx = bytearray(data)  # pymodbus hands over the whole receive buffer so far
        return data

    def _new_client(self) -> AsyncModbusSerialClient:
        from pymodbus.client import AsyncModbusSerialClient
        from pymodbus.framer import FramerType
        c = self.config
        # retries=0: every failed read is counted here, not hidden by pymodbus retrying;
        # reconnect_delay=0: reconnecting is this driver's decision (and counted)
        return AsyncModbusSerialClient(c.port, framer=FramerType.RTU, baudrate=c.baudrate, bytesize=c.bytesize,
                                       parity=c.parity, stopbits=c.stopbits, timeout=c.timeout, retries=0,
                                       reconnect_delay=0, trace_packet=self._trace_packet)

    async def _close_client(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            client.close()

    async def _connect(self) -> str | None:
        """Connect if needed; None on success, else why not."""
        if self._client is not None and self._client.connected:
            return None
        if self._client is not None:
            self._client.close()
        self._client = self._new_client()
        try:
            ok = await asyncio.wait_for(self._client.connect(), timeout=max(self.config.timeout, 0.5))
        except (TimeoutError, OSError) as exc:
            return f"cannot open the port: {type(exc).__name__}: {exc}"
        if not ok:
            return "cannot open the port (connection refused or device missing)"
        if self.config.port.startswith("socket://"):
            _send_immediately(self._client)
        return None

    async def _read_once(self) -> tuple[float, int, float] | ReadFailure:
        """One request; (t_mid on the clock, raw value, round trip in clock s) or the ``ReadFailure``."""
        from pymodbus.exceptions import ConnectionException, ModbusIOException
        why = await self._connect()
        if why is not None:
            return ReadFailure(Failure.CONNECTION, why)
        client = self._client
        assert client is not None, "_connect() succeeded: the client is connected"
        c = self.config
        self._rx = bytearray()
        read = client.read_holding_registers if c.register_type == "holding" else client.read_input_registers
        t_send = self.clock.now()
        try:
            reply = await read(c.register, count=c.registers, device_id=c.device_id)
        except ModbusIOException:
            if bad_crc(bytes(self._rx)):
                return ReadFailure(Failure.CRC, f"reply with a bad CRC ({bytes(self._rx).hex(' ')})")
            return ReadFailure(Failure.TIMEOUT, f"no reply within {c.timeout:g} s")
        except ConnectionException as exc:
            return ReadFailure(Failure.CONNECTION, f"link lost ({exc})")
        t_reply = self.clock.now()
        if reply.isError():
            code = reply.exception_code
            meaning = {1: "illegal function", 2: "illegal data address", 3: "illegal data value",
                       4: "device failure", 6: "device busy"}.get(code, "exception")
            return ReadFailure(Failure.EXCEPTION, f"exception reply {code} ({meaning}) reading {c.registers} "
                                                  f"register(s) at {c.register} ({c.register_type})")
        regs = list(reply.registers)
        if len(regs) != c.registers:
            return ReadFailure(Failure.EXCEPTION, f"expected {c.registers} register(s), got {len(regs)}")
        # int() of an int: uint32 decodes to one already
        value = regs[0] if c.registers == 1 else int(from_registers(regs, "uint32", c.word_order))
        with self._lock:
            self._counts["rtt_max_s"] = max(self._counts["rtt_max_s"], t_reply - t_send)
        return 0.5 * (t_send + t_reply), value, t_reply - t_send

    def _late(self, rtt: float) -> bool:
        """Whether this round trip is too long for its midpoint to date the sample.

        The reference is the recent short round trips (the 10th percentile of the last 256), not a
        typical one: while a busy host delays most replies a median would follow them up. The
        excess allowed over it is (late_reply_factor − 1) times the shortest such reference of the
        capture, the link's own round trip: it does not grow while the host is busy, so a kept
        sample's time is off by at most a quarter of that (factor 1.5). At least the tenth of the
        replies at or under the reference is always kept: a link that slows down for good is followed.
        """
        recent = self._rtts
        late = False
        if self.config.late_reply_factor and len(recent) >= 16:
            k = len(recent) // 10
            reference = float(np.partition(np.fromiter(recent, dtype=float), k)[k])
            self._rtt_floor = min(self._rtt_floor, reference)
            late = rtt > reference + (self.config.late_reply_factor - 1.0) * self._rtt_floor
        recent.append(rtt)
        return late

    async def _sample_loop(self) -> None:
        c = self.config
        self._rtts.clear()
        self._rtt_floor = math.inf
        next_start = 0.0
        while self._sampling:
            if c.min_interval > 0:
                wait = next_start - time.perf_counter()
                if wait > 0:
                    await asyncio.sleep(wait)
                next_start = time.perf_counter() + c.min_interval
            outcome = await self._read_once()
            failed = None
            with self._lock:
                counts = self._counts
                counts["requests"] += 1
                if isinstance(outcome, ReadFailure):
                    failed, detail = outcome.kind, outcome.detail
                    counts[failed.value] += 1
                    counts["consecutive_errors"] += 1
                    counts["max_run_of_errors"] = max(counts["max_run_of_errors"], counts["consecutive_errors"])
                    if counts["consecutive_errors"] >= c.max_consecutive_errors:
                        fault = EncoderFault(
                            f"encoder fault: {counts['consecutive_errors']} failed reads in a row from {self._where()}; "
                            f"last: {detail} (timeouts {counts['timeouts']}, CRC errors {counts['crc_errors']}, "
                            f"exception replies {counts['exceptions']}, connection errors {counts['connection_errors']})",
                            self._snapshot())
                        log.error("%s", fault)
                        self._buffer.fail(fault)
                        return
                elif self._late(outcome[2]):
                    counts["consecutive_errors"] = 0
                    counts["late_replies"] += 1
                else:
                    counts["consecutive_errors"] = 0
                    t, value, _ = outcome
                    angle = c.counts_to_angle(value)
                    if self._unwrap_last is not None:
                        # keep the angle continuous across the encoder's 0/full-turn wrap
                        angle += 2 * math.pi * round((self._unwrap_last - angle) / (2 * math.pi))
                    self._unwrap_last = angle
                    self._buffer.add(t, angle)
            if failed is Failure.CONNECTION:
                # a refused connection fails instantly: pace the retries at the request time-out
                await asyncio.sleep(c.timeout)
            elif failed is Failure.TIMEOUT:
                # An RTU reply carries no transaction id: one that comes after its time-out, while
                # the next request is in flight, would be taken for that request's answer, an angle
                # read one request earlier. The line is let go quiet first; a reply arriving
                # meanwhile finds no request waiting (pymodbus drops it) and is counted.
                self._rx = bytearray()
                await asyncio.sleep(c.timeout)
                if self._rx:
                    with self._lock:
                        self._counts["stale_replies"] += 1
