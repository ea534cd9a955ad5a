"""``[mqtt]``: the broker connection and the topics (no paho here: the configuration reads it)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from service.errors import ConfigError
from service.settings.checks import Check, readable_files
from service.settings.schema import PublisherTable


@dataclass(frozen=True)
class MqttSettings:
    """Broker connection and topics (SI units). Each key's meaning and limits: ``KEYS`` below, from which the
    configuration's ``[mqtt]`` table is built."""

    host: str = "localhost"
    port: int = 1883
    prefix: str = "moi"
    client_id: str | None = None
    username: str | None = None
    password: str | None = None
    password_file: str | None = None
    keepalive: int = 30
    tls: bool = False
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None
    tls_insecure: bool = False
    reconnect_min: float = 0.5
    reconnect_max: float = 30.0
    resend_after: float = 30.0
    window: int = 10
    home_assistant: bool = False
    discovery_prefix: str = "homeassistant"
    protocol: str = "5"


#: the values of ``protocol``
PROTOCOLS = ("5", "3.1.1")


#: each key of the configuration's ``[mqtt]`` table: what it means, its unit and its limits (the table is
#: built from this and the dataclass's fields: ``service.config.appliance.SCHEMA``)
KEYS: dict[str, dict] = {
    "host": dict(doc="broker host"),
    "port": dict(doc="broker port", min=1, max=65535),
    "prefix": dict(doc="topic prefix: topics are <prefix>/<device id>/..."),
    "client_id": dict(doc="MQTT client id (default moi-<device id>-<8 hex digits from this machine and the state "
                      "directory>: unique per appliance)"),
    "username": dict(doc=""),
    "password": dict(doc="prefer password_file"),
    "password_file": dict(doc="file holding the password (e.g. a systemd credential)", kind="path"),
    "keepalive": dict(doc="s", min=5, max=3600),
    "tls": dict(doc="connect with TLS"),
    "ca_file": dict(doc="CA certificate(s) for the broker (default: the system's)", kind="path"),
    "cert_file": dict(doc="client certificate (mutual TLS)", kind="path"),
    "key_file": dict(doc="client key (mutual TLS)", kind="path"),
    "tls_insecure": dict(doc="skip the broker host name check (testing only)"),
    "reconnect_min": dict(doc="first reconnect delay, s", min=0, min_open=True),
    "reconnect_max": dict(doc="longest reconnect delay, s", min=0, min_open=True),
    "resend_after": dict(doc="re-send a result not acknowledged after this, s", min=0, min_open=True),
    "window": dict(doc="results in flight (published, not yet acknowledged) at most", min=1, max=1000),
    "home_assistant": dict(doc="publish Home Assistant discovery messages"),
    "discovery_prefix": dict(doc="Home Assistant discovery prefix"),
    "protocol": dict(doc="MQTT protocol version: \"5\" (command replies on the command's response topic with its "
                     "correlation data) or \"3.1.1\" for a broker that speaks only that (replies on "
                     "<prefix>/<device id>/reply)", choices=PROTOCOLS),
}


def _check(m: dict[str, Any], fail: Callable[[str, str], ConfigError]) -> None:
    if m["password"] is not None and m["password_file"] is not None:
        raise fail("password", "give password or password_file, not both")
    if (m["password"] is not None or m["password_file"] is not None) and m["username"] is None:
        raise fail("username", "missing: a password needs a username")
    if (m["cert_file"] is None) != (m["key_file"] is None):
        raise fail("cert_file", "give both cert_file and key_file for mutual TLS, or neither")
    if not m["tls"] and any(m[k] for k in ("ca_file", "cert_file", "key_file")):
        raise fail("tls", "ca_file/cert_file/key_file are set but tls = false")
    if m["reconnect_max"] < m["reconnect_min"]:
        raise fail("reconnect_max", "must be >= reconnect_min")
    if not m["prefix"].strip("/") or any(ch in m["prefix"] for ch in "#+"):
        raise fail("prefix", f"expected topic levels without '#' or '+', got {m['prefix']!r}")


def _start_checks(m: MqttSettings) -> list[Check]:
    """The password and TLS files it names, readable."""
    return readable_files(((m.password_file, "MQTT password_file"), (m.ca_file, "MQTT ca_file"),
                           (m.cert_file, "MQTT cert_file"), (m.key_file, "MQTT key_file")))


#: the configuration's ``[mqtt]`` table: off unless the file has it
TABLE = PublisherTable(MqttSettings, KEYS, enabled="publish over MQTT (the table's presence enables it)",
                       check=_check, start_checks=_start_checks)
