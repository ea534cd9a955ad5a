"""``[modbus]``: where and how the register map is served (no pymodbus here: the configuration reads it)."""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

#: clients on this machine are always allowed (local tools: ``moi modbus-map --read``, the web page)
_THIS_MACHINE = (ipaddress.ip_network("127.0.0.1/32"), ipaddress.ip_network("::1/128"))


@dataclass(frozen=True)
class ModbusSettings:
    """Where and how to serve (see ``[modbus]`` in docs/service.md).

    mode: "tcp" | "rtu". host/port: TCP listen address (port 0: any free port).
    max_connections: TCP clients served at once; one more closes the connection idle the
    longest. idle_timeout: a TCP connection without a request for this long is closed, s
    (0: never). Both keep the descriptors a client can hold bounded.
    allow_from: TCP client addresses or networks ("192.168.10.20", "10.0.0.0/24") allowed
    to connect besides this machine (127.0.0.1, ::1); empty: every client that reaches
    ``host``. Modbus has no authentication: the default host 127.0.0.1 keeps the trigger
    and abort coils on this machine, and opening them to a network is a choice made by
    setting ``host``, best with ``allow_from``.
    serial_port, baudrate, parity ("N"|"E"|"O"), stopbits, bytesize: RTU line
    (serial_port may be "socket://HOST:PORT" for a serial-over-TCP bridge).
    unit_id: the Modbus device id answered. word_order: "big" | "little".
    result_handshake: "latest" (the block shows the latest result; the PLC reads `seq` before and after)
    | "ack" (results queue until the PLC acknowledges each by writing its `seq` to `result_ack`; a
    result that finds ``queue_depth`` results waiting is counted in `overrun_count`, not shown).
    plc_heartbeat_timeout: the PLC's heartbeat register unchanged this long raises plc_heartbeat_lost, s
    (0: no watchdog).
    """

    mode: str = "tcp"
    host: str = "127.0.0.1"
    port: int = 5020
    unit_id: int = 1
    word_order: str = "big"
    max_connections: int = 16
    idle_timeout: float = 60.0
    allow_from: tuple[str, ...] = ()
    serial_port: str | None = None
    baudrate: int = 19200
    parity: str = "E"
    stopbits: int = 1
    bytesize: int = 8
    result_handshake: str = "latest"
    queue_depth: int = 8
    plc_heartbeat_timeout: float = 0.0


#: the values of ``result_handshake``
RESULT_HANDSHAKES = ("latest", "ack")


def allowed_networks(allow_from: tuple[str, ...]) -> tuple[ipaddress.IPv4Network | ipaddress.IPv6Network, ...]:
    """The networks of ``allow_from`` (ValueError naming a malformed entry)."""
    nets = []
    for entry in allow_from:
        try:
            nets.append(ipaddress.ip_network(entry.strip(), strict=False))
        except ValueError:
            raise ValueError(f"{entry!r} is not an IP address or network (e.g. \"192.168.10.20\", "
                             "\"10.0.0.0/24\")") from None
    return tuple(nets)


def network_exposure(settings: "ModbusSettings") -> str | None:
    """A warning when the TCP server is reachable beyond this machine, else None."""
    if settings.mode != "tcp":
        return None
    try:
        if ipaddress.ip_address(settings.host).is_loopback:
            return None
    except ValueError:
        if settings.host == "localhost":
            return None
    who = ("clients in allow_from " + ", ".join(settings.allow_from)) if settings.allow_from else "every client that reaches it"
    return (f"Modbus TCP listens on {settings.host}, not only on this machine: {who} can trigger and abort "
            "measurements (Modbus has no authentication)")
