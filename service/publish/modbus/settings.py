"""``[modbus]``: where and how the register map is served (no pymodbus here: the configuration reads it)."""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from drivers.modbus_words import WORD_ORDERS
from service.errors import ConfigError
from service.settings.checks import Check, bindable
from service.settings.schema import PublisherTable

#: clients on this machine are always allowed (local tools: ``moi modbus-map --read``, the web page)
_THIS_MACHINE = (ipaddress.ip_network("127.0.0.1/32"), ipaddress.ip_network("::1/128"))


@dataclass(frozen=True)
class ModbusSettings:
    """Where and how the register map is served (SI units). Each key's meaning and limits: ``KEYS`` below, from
    which the configuration's ``[modbus]`` table is built.

    Modbus has no authentication: the default host 127.0.0.1 keeps the trigger and abort coils on this
    machine, and opening them to a network is a choice made by setting ``host``, best with ``allow_from``;
    ``max_connections`` and ``idle_timeout`` keep the descriptors a client can hold bounded.
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


#: each key of the configuration's ``[modbus]`` table: what it means, its unit and its limits (the table is
#: built from this and the dataclass's fields: ``service.config.appliance.SCHEMA``)
KEYS: dict[str, dict] = {
    "mode": dict(doc="Modbus TCP server or Modbus RTU slave on a serial line", choices=("tcp", "rtu")),
    "host": dict(doc="TCP listen address"),
    "port": dict(doc="TCP port (502 needs CAP_NET_BIND_SERVICE; 0: any free port)", min=0, max=65535),
    "unit_id": dict(doc="Modbus unit (device) id answered", min=1, max=247),
    "word_order": dict(doc="order of the two registers of a float32/uint32", choices=WORD_ORDERS),
    "max_connections": dict(doc="TCP clients at once; one more closes the connection idle the longest", min=1, max=256),
    "idle_timeout": dict(doc="close a TCP connection without a request for this long, s (0: never)", min=0),
    "allow_from": dict(doc="TCP client addresses or networks allowed besides this machine, e.g. [\"192.168.10.20\", "
                       "\"10.0.0.0/24\"] (empty: every client that reaches host)"),
    "serial_port": dict(doc="RTU: serial device, e.g. /dev/ttyAMA0"),
    "baudrate": dict(doc="RTU baud rate", min=300, max=4_000_000),
    "parity": dict(doc="RTU parity", choices=("N", "E", "O")),
    "stopbits": dict(doc="RTU stop bits", choices=(1, 2)),
    "bytesize": dict(doc="RTU data bits", choices=(7, 8)),
    "result_handshake": dict(doc="\"latest\": the result block shows the latest result (read seq before and after); "
                             "\"ack\": results queue until the PLC acknowledges each in register result_ack "
                             "(docs/modbus.md)", choices=RESULT_HANDSHAKES),
    "queue_depth": dict(doc="result_handshake = \"ack\": results queued for the PLC at most; one more is counted "
                        "in overrun_count", min=1, max=1000),
    "plc_heartbeat_timeout": dict(doc="the PLC's heartbeat register (114) unchanged this long raises "
                                  "plc_heartbeat_lost, s (0: no watchdog)", min=0, max=3600),
}


def _check(mb: dict[str, Any], fail: Callable[[str, str], ConfigError]) -> None:
    if mb["mode"] == "rtu" and not mb["serial_port"]:
        raise fail("serial_port", "missing: mode = \"rtu\" needs the serial device, e.g. /dev/ttyAMA0")
    mb["allow_from"] = tuple(mb["allow_from"] or ())
    try:
        allowed_networks(mb["allow_from"])
    except ValueError as exc:
        raise fail("allow_from", str(exc)) from None


def _start_checks(mb: ModbusSettings) -> list[Check]:
    """The TCP port free and who can reach it; or the RTU serial device present."""
    if mb.mode == "tcp":
        checks = [bindable(mb.host, mb.port, "Modbus TCP port")]
        exposure = network_exposure(mb)
        if exposure is not None:
            checks.append(Check("Modbus exposure", True, exposure + ("" if mb.allow_from else
                                "; name the PLCs in [modbus] allow_from"), warning=not mb.allow_from))
        return checks
    if mb.serial_port and "://" not in mb.serial_port:
        ok = Path(mb.serial_port).exists()
        return [Check("Modbus RTU port", ok, mb.serial_port + (" present" if ok else " does not exist"))]
    return []


def _descriptors(mb: ModbusSettings) -> dict[str, int]:
    return {"Modbus": mb.max_connections} if mb.mode == "tcp" else {}


#: the configuration's ``[modbus]`` table: on (with its defaults) without the table
TABLE = PublisherTable(ModbusSettings, KEYS, enabled="serve the registers", on_without_table=True, check=_check,
                       start_checks=_start_checks, descriptors=_descriptors)
