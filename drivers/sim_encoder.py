"""The simulated encoder: a real pymodbus RTU server whose position register follows a pendulum.

It listens on ``socket://127.0.0.1:PORT`` (RTU frames over loopback TCP, the
URL pyserial and pymodbus understand), so ``drivers.encoder.ModbusEncoder``
talks to it through exactly the code path it uses on an RS-485 adapter.

On every read request the server latches the position from the angle source
halfway through the configured latency (its turnaround) on the injected clock
(real or scaled time), adds noise, quantises to the encoder's counts, and
replies at the end of it.
With ``baudrate`` set it also spends the request's wire time before latching
and the reply's after, as a real RS-485 line does. Faults
are injected on the wire: dropped replies (no answer: the client times out)
and CRC corruption (the last byte flipped: the client's framer rejects it), and
glitches (a position 1/128 turn off behind a correct CRC).
A read outside the position registers gets an ILLEGAL DATA ADDRESS
exception reply, like a real device.
"""

from __future__ import annotations

import asyncio
import logging
import math
import socket
import threading
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer
from pymodbus.simulator import DataType, SimData, SimDevice

from .aioloop import LoopThread
from .clock import Clock
from .encoder import EncoderConfig, check_register_layout
from .errors import DriverConfigError, DriverError
from .modbus_words import to_registers
from .sensor import AngleSource

log = logging.getLogger("moi.drivers.sim_encoder")

#: Modbus function codes that read the position (holding / input registers)
_READ_CODES = (3, 4)

#: shorter waits (s) are slept on the server's thread: the event loop's own timer is only ms-precise
_SHORTEST_ASYNC_WAIT = 0.002


@dataclass(frozen=True)
class SimEncoderConfig:
    """What the simulated encoder looks like on the bus and how imperfect it is.

    device_id: Modbus device (slave) id, 1..247.
    register: address of the (first) position register; registers: 1 (16-bit) or 2 (32-bit).
    word_order: "big" (high word first) or "little", for 2 registers.
    counts_per_turn: encoder resolution, counts per revolution (2**17 for 17 bits).
    multi_turn: False: the value wraps every turn (0 … counts_per_turn−1);
        True: the value counts turns too (two's complement over the register width).
    direction: +1, or −1 when the encoder counts against the rig's positive angle.
    zero: counts reported at angle 0 (mounting offset).
    noise_std: white noise added to the true angle before quantisation, rad.
    latency: encoder turnaround, from the request's last byte to the reply, s of real time;
        the position is latched halfway through it.
    baudrate: if set, the request's wire time passes before the latch and the reply's
        after it, at this baud rate (11 bits per character with parity, 10 without).
    parity: "N", "E" or "O" (only used for the wire time).
    drop_rate: fraction of replies never sent (0…1).
    crc_error_rate: fraction of replies sent with a corrupted CRC (0…1).
    glitch_rate: fraction of positions latched 1/128 turn off, with a correct CRC (0…1): a
        corrupted reading no framing check can catch (the identification must).
    seed: random seed for noise and fault injection.
    """

    device_id: int = 1
    register: int = 0
    registers: int = 2
    word_order: str = "big"
    counts_per_turn: int = 1 << 17
    multi_turn: bool = False
    direction: int = 1
    zero: int = 0
    noise_std: float = 0.0
    latency: float = 0.0
    baudrate: int | None = None
    parity: str = "N"
    drop_rate: float = 0.0
    crc_error_rate: float = 0.0
    glitch_rate: float = 0.0
    seed: int | None = None

    def __post_init__(self) -> None:
        check_register_layout(self.device_id, self.register, self.registers, self.word_order,
                              self.counts_per_turn, self.direction, what="simulated encoder")
        for name in ("noise_std", "latency"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise DriverConfigError(f"simulated encoder: {name} must be >= 0, got {v!r}")
        for name in ("drop_rate", "crc_error_rate", "glitch_rate"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0 <= v < 1):
                raise DriverConfigError(f"simulated encoder: {name} must be a fraction in [0, 1), got {v!r}")
        if self.baudrate is not None and not (isinstance(self.baudrate, int) and self.baudrate > 0):
            raise DriverConfigError(f"simulated encoder: baudrate must be a positive integer or None, got {self.baudrate!r}")
        if self.parity not in ("N", "E", "O"):
            raise DriverConfigError(f"simulated encoder: parity must be 'N', 'E' or 'O', got {self.parity!r}")

    def counts(self, angle: float) -> int:
        """The register value (unsigned, over the register width) for a measured angle in rad."""
        c = self.zero + self.direction * round(angle / (2 * math.pi) * self.counts_per_turn)
        width = 16 * self.registers
        if self.multi_turn:
            return c % (1 << width)
        return c % self.counts_per_turn

    def wire_times(self, count: int) -> tuple[float, float]:
        """Seconds the request and the reply of a read of ``count`` registers spend on the wire at ``baudrate``."""
        if not self.baudrate:
            return 0.0, 0.0
        bits = 11 if self.parity != "N" else 10
        return 8 * bits / self.baudrate, (5 + 2 * count) * bits / self.baudrate


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free on ``host`` a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


class SimEncoderServer:
    """A pymodbus RTU server on ``socket://host:port`` serving a simulated absolute encoder.

    angle_source: time on ``clock`` (s) → true angle (rad), e.g. ``SimRig.angle``.
    clock: the clock shared with the client (ScaledClock or MonotonicClock).
    config: bus layout and imperfections (``SimEncoderConfig``).
    port: 0 picks a free port.

    ``counts`` reports what happened: reads (positions latched), replies sent, dropped, corrupted, exceptions.
    Start with ``start()`` (or ``with``), stop with ``stop()``; both safe twice.
    """

    def __init__(self, angle_source: AngleSource, clock: Clock, config: SimEncoderConfig | None = None, *,
                 host: str = "127.0.0.1", port: int = 0):
        self.config = config or SimEncoderConfig()
        self.host = host
        self.port = port or free_tcp_port(host)
        self._angle = angle_source
        self._clock = clock
        self._rng = np.random.default_rng(self.config.seed)
        self._io = LoopThread(f"moi-sim-encoder-{self.port}")
        self._server: ModbusSerialServer | None = None
        self._lock = threading.Lock()
        self.counts = {"reads": 0, "replies": 0, "dropped": 0, "corrupted": 0, "exceptions": 0, "glitches": 0}

    @property
    def url(self) -> str:
        """The port string a client opens: ``socket://host:port``."""
        return f"socket://{self.host}:{self.port}"

    @property
    def running(self) -> bool:
        return self._io.running

    def encoder_config(self, **overrides: Any) -> EncoderConfig:
        """An ``EncoderConfig`` matching this server (port, id, registers, resolution, direction, zero)."""
        c = self.config
        base = EncoderConfig(port=self.url, device_id=c.device_id, register=c.register, registers=c.registers,
                             word_order=c.word_order, counts_per_turn=c.counts_per_turn, direction=c.direction,
                             zero=c.zero, parity=c.parity, baudrate=c.baudrate or 115200)
        return replace(base, **overrides)

    # -- lifecycle -------------------------------------------------------------------
    def start(self, timeout: float = 5.0) -> "SimEncoderServer":
        """Start listening (returns when the port accepts connections)."""
        if self.running:
            return self
        try:
            self._io.start_serving(self._serve(), timeout)
        except TimeoutError:
            raise DriverError(f"simulated encoder did not start within {timeout:g} s on {self.url}") from None
        except Exception as exc:
            raise DriverError(f"simulated encoder cannot listen on {self.url}: {exc}") from exc
        if not self._wait_listening(timeout):
            self.stop()
            raise DriverError(f"simulated encoder on {self.url} does not accept connections")
        log.info("simulated encoder listening on %s", self.url)
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Stop serving and close the port (a connected client sees the connection drop)."""
        if self._io.running and self._server is not None:
            try:
                self._io.call(self._server.shutdown(), timeout)
            except Exception:  # the loop may already be going down; stopping it below is what matters
                log.debug("simulated encoder shutdown raised", exc_info=True)
        self._server = None
        self._io.stop(timeout)

    def __enter__(self) -> "SimEncoderServer":
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # -- internals -------------------------------------------------------------------
    async def _serve(self) -> None:
        c = self.config
        device = SimDevice(
            id=c.device_id,
            simdata=[SimData(c.register, count=c.registers, values=0, datatype=DataType.REGISTERS, readonly=True)],
            action=self._on_access,
        )
        self._server = ModbusSerialServer(device, framer=FramerType.RTU, port=self.url, baudrate=c.baudrate or 115200,
                                          parity=c.parity, trace_packet=self._on_packet)
        await self._server.serve_forever(background=True)

    def _wait_listening(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                with socket.create_connection((self.host, self.port), timeout=0.2):
                    return True
            except OSError:
                time.sleep(0.01)
        return False

    async def _on_access(self, function_code: int, start_address: int, address: int, count: int,
                         registers: list[int], set_values: Any) -> ExcCodes | None:
        c = self.config
        if function_code not in _READ_CODES or set_values is not None:
            return ExcCodes.ILLEGAL_FUNCTION
        request_wire, reply_wire = c.wire_times(count)
        # the request's wire time, then the first half of the turnaround: the simulated device runs on the host,
        # so a busy host stretches its turnaround, which a real encoder's does not; latching midway keeps the
        # stretch symmetric about the latch, out of the client's midpoint timestamp
        await self._wait(request_wire + 0.5 * c.latency)
        t = self._clock.now()
        true_angle = float(self._angle(t))
        measured = true_angle + (self._rng.normal(0.0, c.noise_std) if c.noise_std else 0.0)
        value = c.counts(measured)
        if c.glitch_rate and self._rng.random() < c.glitch_rate:
            value = c.counts(measured + 2 * math.pi / 128)
            with self._lock:
                self.counts["glitches"] += 1
        offset = c.register - start_address
        if c.registers == 1:
            registers[offset] = value & 0xFFFF
        else:
            registers[offset:offset + 2] = to_registers(value, "uint32", c.word_order)
        with self._lock:
            self.counts["reads"] += 1
        await self._wait(0.5 * c.latency + reply_wire)
        return None

    @staticmethod
    async def _wait(seconds: float) -> None:
        """Let ``seconds`` of real time pass on the device's loop."""
        if seconds > _SHORTEST_ASYNC_WAIT:
            await asyncio.sleep(seconds)
        elif seconds > 0:
            # the event loop waits in whole milliseconds (epoll): 0.2 ms would become >= 1 ms, a round
            # trip 3× the wire's and a third of the samples; this loop serves only this simulated device,
            # which is busy during its turnaround anyway
            time.sleep(seconds)

    def _on_packet(self, sending: bool, data: bytes) -> bytes:
        if not sending or not data:
            return data
        c = self.config
        if len(data) >= 3 and data[1] & 0x80:
            with self._lock:
                self.counts["exceptions"] += 1
        u = self._rng.random()
        with self._lock:
            if u < c.drop_rate:
                self.counts["dropped"] += 1
                return b""
            if u < c.drop_rate + c.crc_error_rate:
                self.counts["corrupted"] += 1
                self.counts["replies"] += 1
                return data[:-1] + bytes([data[-1] ^ 0x5A])
            self.counts["replies"] += 1
        return data
