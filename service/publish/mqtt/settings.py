"""``[mqtt]``: the broker connection and the topics (no paho here: the configuration reads it)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MqttSettings:
    """Broker connection and topics (``[mqtt]`` in the config file).

    keepalive, reconnect_min/max, resend_after: s. protocol: "5" (MQTT 5: a command's reply goes to its
    response topic with its correlation data) or "3.1.1" (a broker that speaks only that: replies go to
    ``<prefix>/<device id>/reply``).
    """

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
