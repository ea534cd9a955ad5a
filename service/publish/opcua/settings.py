"""``[opcua]``: where and how the OPC UA server serves (no asyncua here: the configuration reads it)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from service.errors import ConfigError
from service.names import name_problem
from service.settings.checks import Check, bindable, readable_files
from service.settings.schema import PublisherTable


@dataclass(frozen=True)
class OpcUaSettings:
    """Where and how the OPC UA server serves (off unless the ``[opcua]`` table is given). Each key's meaning and
    limits: ``KEYS`` below, from which the configuration's table is built."""

    host: str = "127.0.0.1"
    port: int = 4840
    username: str | None = None
    password: str | None = None
    password_file: str | None = None
    anonymous: bool = False
    allow_unencrypted: bool = False
    certificate: str | None = None
    private_key: str | None = None
    cache_file: str | None = None
    trusted_clients: str | None = None
    manufacturer: str = "moi"
    model: str = "pendulum inertia appliance"
    serial_number: str | None = None
    results_kept: int = 100
    max_connections: int = 16
    login_timeout: float = 30.0
    max_nodes_per_request: int = 1000


#: each key of the configuration's ``[opcua]`` table: what it means, its unit and its limits (the table is
#: built from this and the dataclass's fields: ``service.config.appliance.SCHEMA``)
KEYS: dict[str, dict] = {
    "host": dict(doc="listen address (127.0.0.1: this machine only; 0.0.0.0: every interface)"),
    "port": dict(doc="TCP port (0: any free port)", min=0, max=65535),
    "username": dict(doc="the user an OPC UA client logs in as"),
    "password": dict(doc="prefer password_file"),
    "password_file": dict(doc="file holding the password (e.g. a systemd credential)", kind="path"),
    "anonymous": dict(doc="let clients in without a user (read and call the methods)"),
    "allow_unencrypted": dict(doc="also offer the endpoint without security (default: Basic256Sha256 Sign & Encrypt "
                              "only)"),
    "certificate": dict(doc="the server's certificate, DER (default: opcua/server-cert.der in the state directory; "
                        "made self-signed on first start)", kind="path"),
    "private_key": dict(doc="the server's private key, PEM (default: opcua/server-key.pem in the state directory)",
                        kind="path"),
    "cache_file": dict(doc="asyncua's cache of the standard address space (default: opcua/address-space in the state "
                       "directory; made on first start, read on every later one; only where Python has gdbm or ndbm, "
                       "e.g. Debian's python3-gdbm: with dbm.dumb alone, building it is faster)", kind="path"),
    "trusted_clients": dict(doc="directory of the client application certificates (DER or PEM) admitted (default: "
                            "any client certificate; the user and password decide)", kind="path"),
    "manufacturer": dict(doc="MachineIdentification Manufacturer"),
    "model": dict(doc="MachineIdentification Model"),
    "serial_number": dict(doc="MachineIdentification SerialNumber (default: the device id)"),
    "results_kept": dict(doc="results GetResultById finds in memory (older ones: from the store)", min=1,
                         max=100000),
    "max_connections": dict(doc="connections served at once (at the cap, the oldest without a login makes room): far "
                            "below the daemon's descriptor limit, which the measurement, the store and the PLC share",
                            min=1, max=256),
    "login_timeout": dict(doc="a connection that has not logged in after this long is closed, s", min=1.0,
                          max=600.0),
    "max_nodes_per_request": dict(doc="nodes one Read, Write, Browse, Call or monitored-item request may name",
                                  min=10, max=100000),
}


def _check(o: dict[str, Any], fail: Callable[[str, str], ConfigError]) -> None:
    if o["username"] is not None and (problem := name_problem("user", o["username"])) is not None:
        raise fail("username", problem)
    if o["password"] is not None and o["password_file"] is not None:
        raise fail("password", "give password or password_file, not both")
    if o["username"] is None and not o["anonymous"]:
        raise fail("username", "missing: no client could log in (give username and password_file, or set "
                               "anonymous = true)")
    if o["username"] is not None and o["password"] is None and o["password_file"] is None:
        raise fail("password_file", "missing: the user needs a password")


def _doors(ua: OpcUaSettings) -> list[Check]:
    """The server's trusted clients (a directory, as the start needs) and who may come in unencrypted or
    without a user."""
    checks = []
    if ua.trusted_clients is not None:
        ok = Path(ua.trusted_clients).is_dir()
        checks.append(Check("OPC UA trusted_clients", ok, ua.trusted_clients + ("" if ok else " is not a directory")))
    if ua.anonymous or ua.allow_unencrypted:
        doors = [d for d, on in (("clients without a user (anonymous = true)", ua.anonymous),
                                 ("unencrypted sessions (allow_unencrypted = true)", ua.allow_unencrypted)) if on]
        checks.append(Check("OPC UA exposure", True, f"{' and '.join(doors)} on {ua.host}:{ua.port}", warning=True))
    return checks


def _start_checks(ua: OpcUaSettings) -> list[Check]:
    """Its port free, its files readable, its doors."""
    # a certificate or key not there yet is made at the first start: checked only when it exists
    made = tuple((p, w) for p, w in ((ua.certificate, "OPC UA certificate"), (ua.private_key, "OPC UA private_key"))
                 if p and Path(p).exists())
    return [bindable(ua.host, ua.port, "OPC UA port"),
            *readable_files(((ua.password_file, "OPC UA password_file"), *made)), *_doors(ua)]


#: the configuration's ``[opcua]`` table: off unless the file has it
TABLE = PublisherTable(OpcUaSettings, KEYS, enabled="serve OPC UA (the table's presence enables it)", check=_check,
                       start_checks=_start_checks, descriptors=lambda ua: {"OPC UA": ua.max_connections})
