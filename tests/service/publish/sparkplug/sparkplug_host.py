"""A Sparkplug B host application for the tests: a real MQTT client that decodes with pysparkplug.

pysparkplug is an implementation of the Sparkplug B specification independent of the appliance's (its
protobuf module is generated from the specification's ``.proto``): what it decodes, a SCADA host
decodes. The host announces itself with a retained STATE (online / offline, with a last will), reads
every message of a group, keeps the device's birth to decode aliases, and sends NCMD / DCMD.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import paho.mqtt.client as mqtt
import pytest
from paho.mqtt.enums import CallbackAPIVersion

ps = pytest.importorskip("pysparkplug", reason="the Sparkplug host decodes with pysparkplug (`make install`)")
from pysparkplug import _protobuf as spb  # noqa: E402  (its generated Payload message: properties too)


@dataclass
class Received:
    kind: str            # NBIRTH, DBIRTH, DDATA, NDEATH, NCMD ...
    topic: str
    raw: bytes
    decoded: Any         # the pysparkplug payload object
    wire: Any            # the generated protobuf message (properties, is_historical)


class SparkplugHost:
    """A host application with id ``host_id`` subscribed to ``spBv1.0/<group>/#``. persistent: a persistent
    session (the broker queues the QoS 1 results for it while it reconnects)."""

    def __init__(self, port: int, group: str = "moi", host_id: str = "scada", persistent: bool = False) -> None:
        self.group, self.host_id = group, host_id
        self.state_topic = f"spBv1.0/STATE/{host_id}"
        self.received: list[Received] = []
        self.births: dict[str, Any] = {}  # DBIRTH per device topic (for aliases)
        self._cond = threading.Condition()
        self._subscribed = threading.Event()
        self.errors: list[str] = []
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=f"host-{host_id}",
                                  clean_session=not persistent)
        self.client.reconnect_delay_set(0.1, 0.5)  # type: ignore[arg-type]
        self.client.will_set(self.state_topic, self._state(False), qos=1, retain=True)
        self._online = False  # announced online: announced again at each reconnect, as a host does
        self.client.on_connect = self._on_connect
        self.client.on_subscribe = lambda *a: self._subscribed.set()
        self.client.on_message = self._on_message
        self.client.connect_async("127.0.0.1", port, keepalive=10)
        self.client.loop_start()
        assert self._subscribed.wait(10), "the Sparkplug host did not subscribe"

    def _on_connect(self, client, userdata, flags, rc, props) -> None:
        client.subscribe([(f"spBv1.0/{self.group}/#", 1)])
        if self._online:
            client.publish(self.state_topic, self._state(True), qos=1, retain=True)

    @staticmethod
    def _state(online: bool) -> str:
        return json.dumps({"online": online, "timestamp": int(time.time() * 1000)})

    def online(self, online: bool = True) -> None:
        """Publish this host's retained STATE."""
        self._online = online
        self.client.publish(self.state_topic, self._state(online), qos=1, retain=True).wait_for_publish(5)

    def _on_message(self, client, userdata, msg) -> None:
        parts = msg.topic.split("/")
        kind = parts[2]
        raw = bytes(msg.payload)
        try:
            wire = spb.Payload.FromString(raw)
            cls = {"NBIRTH": ps.NBirth, "DBIRTH": ps.DBirth, "NDEATH": ps.NDeath, "DDEATH": ps.DDeath,
                   "NDATA": ps.NData, "DDATA": ps.DData, "NCMD": ps.NCmd, "DCMD": ps.DCmd}[kind]
            birth = self.births.get("/".join(parts[3:])) if kind == "DDATA" else None
            decoded = cls.decode(raw, birth=birth)
        except Exception as exc:  # recorded: a test asserts there are none
            self.errors.append(f"{msg.topic}: {type(exc).__name__}: {exc}")
            return
        with self._cond:
            if kind == "DBIRTH":
                self.births["/".join(parts[3:])] = decoded
            self.received.append(Received(kind, msg.topic, raw, decoded, wire))
            self._cond.notify_all()

    def of(self, kind: str) -> list[Received]:
        with self._cond:
            return [r for r in self.received if r.kind == kind]

    def wait(self, predicate: Callable[["SparkplugHost"], Any], timeout: float, what: str) -> Any:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not (value := predicate(self)):
                left = deadline - time.monotonic()
                if left <= 0:
                    kinds = [r.kind for r in self.received]
                    raise AssertionError(f"timed out after {timeout} s waiting for {what}; received {kinds}; "
                                         f"errors {self.errors}")
                self._cond.wait(left)
            return value

    def count(self, kind: str) -> int:
        return len(self.of(kind))

    def results(self, device: str | None = None) -> list[dict[str, Any]]:
        """Every result DDATA in arrival order, as {metric name: value} (with ``_seq``, ``_historical``)."""
        out = []
        for r in self.of("DDATA"):
            if device is not None and not r.topic.endswith("/" + device):
                continue
            values = {m.name: m.value for m in r.decoded.metrics}
            if "Result/UUID" in values:
                out.append(values | {"_seq": r.decoded.seq, "_historical": any(m.is_historical for m in r.decoded.metrics),
                                     "_device": r.topic.rsplit("/", 1)[-1]})
        return out

    def replies(self) -> list[dict[str, Any]]:
        return [json.loads(m.value) for r in self.of("DDATA") for m in r.decoded.metrics if m.name == "Command/Reply"]

    def command(self, edge: str, device: str | None, metrics: list[tuple[str, Any, Any]]) -> None:
        """NCMD (device None) or DCMD of (name, pysparkplug DataType, value)."""
        ms = tuple(ps.Metric(timestamp=ps.get_current_timestamp(), name=n, datatype=t, value=v) for n, t, v in metrics)
        cls = ps.DCmd if device else ps.NCmd
        self.send(edge, device, cls(timestamp=ps.get_current_timestamp(), metrics=ms).encode(include_dtypes=True))

    def send(self, edge: str, device: str | None, raw: bytes) -> None:
        kind = "DCMD" if device else "NCMD"
        topic = f"spBv1.0/{self.group}/{kind}/{edge}" + (f"/{device}" if device else "")
        self.client.publish(topic, raw, qos=1).wait_for_publish(5)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
