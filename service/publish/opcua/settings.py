"""``[opcua]``: where and how the OPC UA server serves (no asyncua here: the configuration reads it)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class OpcUaSettings:
    """Where and how to serve (``[opcua]`` in the config file; off unless the table is given).

    host/port: the TCP listen address (port 0: any free port). username, password / password_file:
    the one user a client logs in as. anonymous: let a client in without a user (off: OPC UA has
    authentication, use it). allow_unencrypted: also offer the endpoint without security (None);
    by default only Basic256Sha256 Sign & Encrypt is offered. certificate, private_key: the server's
    certificate (DER) and key (PEM), created self-signed on first start when missing (default:
    ``opcua/`` in the state directory). cache_file: asyncua's shelf of the standard address space,
    made on first start, read on every later one (default: ``opcua/address-space`` in the state
    directory). trusted_clients: a directory of the client application certificates (DER or PEM) admitted;
    a client with another certificate is refused before it may log in (None: any client certificate, the
    user and password decide). manufacturer, model, serial_number: MachineIdentification (serial number default:
    the device id). results_kept: results GetResultById finds without reading the store (the newest).
    """

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
