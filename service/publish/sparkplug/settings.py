"""``[sparkplug]``: the Sparkplug B edge node's broker, its identity and its primary host (no paho here)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from service.errors import ConfigError
from service.settings.schema import PublisherTable


@dataclass(frozen=True)
class SparkplugSettings:
    """The edge node's broker and names (SI units). Each key's meaning and limits: ``KEYS`` below."""

    host: str = "localhost"
    port: int = 1883
    group_id: str = "moi"
    edge_node_id: str | None = None
    primary_host: str | None = None
    client_id: str | None = None
    keepalive: int = 30
    reconnect_min: float = 0.5
    reconnect_max: float = 30.0
    resend_after: float = 30.0
    window: int = 10
    state_tolerance: float = 300.0
    rebirth_interval: float = 2.0


KEYS: dict[str, dict] = {
    "host": dict(doc="broker host (the plant's Sparkplug broker; may be the [mqtt] one)"),
    "port": dict(doc="broker port", min=1, max=65535),
    "group_id": dict(doc="Sparkplug group: topics are spBv1.0/<group_id>/<message type>/<edge node>/<device>"),
    "edge_node_id": dict(doc="the edge node's id (default: the [device] id); the appliance is its one device, "
                         "named by the [device] id"),
    "primary_host": dict(doc="the primary host application's id: no birth and no result is sent while its "
                         "STATE says offline (results wait in the outbox and go out in order when it is back); "
                         "unset: publish whenever the broker is reachable"),
    "client_id": dict(doc="MQTT client id (default moi-sparkplug-<edge node id>)"),
    "keepalive": dict(doc="s", min=5, max=3600),
    "reconnect_min": dict(doc="first reconnect delay, s", min=0, min_open=True),
    "reconnect_max": dict(doc="longest reconnect delay, s", min=0, min_open=True),
    "resend_after": dict(doc="re-send a result not acknowledged after this, s", min=0, min_open=True),
    "window": dict(doc="results in flight (published, not yet acknowledged) at most", min=1, max=1000),
    "state_tolerance": dict(doc="a primary host's STATE stamped later than this clock's now plus this is refused "
                            "(logged): the clocks disagree, or it is not the host's, s", min=0, max=86400),
    "rebirth_interval": dict(doc="at most one birth per this interval on Rebirth requests: requests within it are "
                             "answered by one birth at its end, s", min=0, max=3600),
}

#: characters no Sparkplug id may hold (topic level separators and wildcards)
_NOT_IN_IDS = "/#+"


def _check(m: dict[str, Any], fail: Callable[[str, str], ConfigError]) -> None:
    for key in ("group_id", "edge_node_id", "primary_host"):
        value = m[key]
        if value is not None and (not value or any(ch in value for ch in _NOT_IN_IDS)):
            raise fail(key, f"expected a Sparkplug id without '/', '#' or '+', got {value!r}")
    if m["reconnect_max"] < m["reconnect_min"]:
        raise fail("reconnect_max", "must be >= reconnect_min")


#: the configuration's ``[sparkplug]`` table: off unless the file has it
TABLE = PublisherTable(SparkplugSettings, KEYS, enabled="publish as a Sparkplug B edge node (the table's presence "
                       "enables it)", check=_check)
