"""MQTT telemetry (paho-mqtt 2.x, callback API version 2).

Topics under ``<prefix>/<device_id>/`` (prefix default "moi"):

* ``result``      one JSON result per measurement, QoS 1, from the durable outbox
  (``service.persistence.outbox``); consumers dedupe by ``uuid``.
* ``status``      ``online`` / ``offline``, retained; ``offline`` is also the last will.
* ``state``       sequencer events as JSON, retained (the latest state), QoS 0.
* ``cmd/measure`` a message here starts one measurement (like the push button);
  ``cmd/abort`` aborts the running one. A message with the retain flag is the
  broker's stored copy, handed over at a subscription: never a command (a stale
  retained command must not fire at every reconnect; one published with retain
  reaches the subscribed daemon as a plain message and runs once); a JSON payload with an
  ``"id"`` is acted on once per id (QoS 1 may deliver twice). A JSON measure
  command may carry ``"part_id"`` (the part's serial number) and ``"recipe"``.
* ``cmd/recipe``  makes a recipe active: its name or number as the payload, or
  JSON ``{"recipe": name or number}`` (0 or "" deselects).
* ``cmd/part_id`` sets the next part's ID: the ID as the payload, or JSON
  ``{"part_id": text}`` ("" clears it).
* ``reply``       every command's outcome (JSON: command, id, status accepted |
  refused | done | failed, reason, detail; a trigger's result uuid and seq once
  done), unless the command came with an MQTT 5 response topic: then there,
  with its correlation data. Retained and empty messages get no reply.
* ``recipe``, ``part_id`` retained: the active recipe and the next part's ID.
* ``spc/<recipe>`` the SPC summary of a recipe's parts, retained, republished
  after each completed part.

* ``result/last`` a retained copy of the latest delivered result (what Home
  Assistant's sensors read, so they are known again after its restart).

Optional Home Assistant MQTT discovery (retained config messages) for J, its
uncertainty, J_object, ω_n, the damping ratio, the state, the part, each
quality flag (device class "problem" only for the flags that invalidate a
result), a "measure" and an "abort / acknowledge" button, a ``select`` of the
recipe and a ``text`` of the part ID. Entity ids are lower case with
underscores (Home Assistant's rule), every numeric sensor has its unit.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import ssl
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any, Callable, Mapping

import paho.mqtt.client as mqtt
from paho.mqtt.enums import CallbackAPIVersion
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from service.core import vocabulary as V
from service.errors import ConfigError
from service.logs import Throttle
from service.persistence.outbox import OutboxSender
from service.persistence.store import Store
from service.publish.callbacks import never_raises
from service.publish.port import ApplianceView, Publisher
from service.publish.replies import CommandReply

# the settings are read by the configuration without paho; here for the client's users too
from .discovery import discovery_messages
from .settings import MqttSettings
from .topics import Topics

log = logging.getLogger("moi.mqtt")

#: a connection the broker closes within this many seconds of connecting counts towards a takeover, s
TAKEOVER_WINDOW = 10.0
#: after so many such closes in a row the log names the likely cause: another client with this client id
TAKEOVER_DROPS = 3


def default_client_id(device_id: str, store_path: str | os.PathLike) -> str:
    """``moi-<device id>-<tag>``: the tag (8 hex digits) is made from this machine's id and the result store's
    path, stable across restarts; two appliances given the same device id by mistake then do not take each
    other's connection over at the broker (which closes the older one: both reconnect, in turn, for ever)."""
    import hashlib
    import socket

    try:
        machine = Path("/etc/machine-id").read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        machine = ""
    seed = f"{machine or socket.gethostname()}:{Path(store_path).resolve()}"
    return f"moi-{device_id}-{hashlib.sha256(seed.encode()).hexdigest()[:8]}"


#: a command payload longer than this is a command without an id (its JSON is not parsed), bytes
MAX_COMMAND_PAYLOAD = 1024
#: an MQTT 5 response topic is honoured only under the appliance's reply topic and up to this length, characters
MAX_TOPIC = 256
#: correlation data longer than this is not echoed, bytes
MAX_CORRELATION = 128


_never_raises = never_raises(log, "MQTT")


def _command_document(payload: bytes) -> tuple[Any, str | None]:
    """A command's payload read as JSON (None when it is not, or too long to read) and its "id" (for dedupe)."""
    if len(payload) > MAX_COMMAND_PAYLOAD:
        return None, None
    try:
        doc = json.loads(payload)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None, None  # any payload is a valid command; only a JSON "id" is used for dedupe
    return doc, (str(doc["id"])[:128] if isinstance(doc, dict) and doc.get("id") is not None else None)


def _command_data(name: str, payload: bytes, doc: Any) -> tuple[dict[str, Any], str | None]:
    """The data a command carries (the keys its command takes, or a part command's bare name, number or ID),
    and why it is malformed (None: it is not)."""
    keys = V.COMMANDS[name].data or V.PART_DATA  # an abort's are passed on and ignored
    data: dict[str, Any] = {k: doc[k] for k in keys if k in doc} if isinstance(doc, dict) else {}
    if name == V.SET and not isinstance(data.get("action"), str):
        return data, 'expected JSON {"action": "redo" | "skip" | "abort"}'
    if V.COMMANDS[name].act == "part":
        if len(payload) > MAX_COMMAND_PAYLOAD:  # no recipe or part has such a name
            return data, f"{len(payload)} bytes (at most {MAX_COMMAND_PAYLOAD})"
        if not isinstance(doc, dict):  # a bare name, number or ID
            data = {name: payload.decode("utf-8", errors="replace").strip()}
            if data[name].startswith(("{", "[")):  # JSON meant, and broken (or not an object): no name
                return data, f'not JSON {{"{name}": ...}} (nor a {name.replace("_", " ")})'
        if name not in data:
            return data, f'expected the {name.replace("_", " ")} or JSON {{"{name}": ...}}'
    return data, None


class _Client(mqtt.Client):
    """paho's client, telling why a connection attempt failed: paho swallows the error of every
    attempt before the first success (an unresolvable host, a refused port, a TLS failure) and
    reports later ones without the cause."""

    on_connect_error: Callable[[OSError], None] | None = None

    def reconnect(self):
        try:
            return super().reconnect()
        except OSError as exc:  # socket.gaierror, ConnectionRefusedError, ssl.SSLError, TimeoutError ...
            if self.on_connect_error is not None:
                self.on_connect_error(exc)
            raise


class MqttService(Publisher):
    """The MQTT client of the daemon: durable result delivery, status, state, commands.

    on_command(name, source, data, reply) is called from paho's thread for a
    command message ("trigger" or "abort", source "mqtt"; "trigger" with data
    when the message carries a part ID or recipe, "recipe" with data
    {"recipe": ...}, "part_id" with {"part_id": ...}; data None otherwise);
    ``reply`` publishes the outcome. It must not block.
    """

    def __init__(self, settings: MqttSettings, device_id: str, store: Store, *, software_version: str = "",
                 on_command: Callable[..., None] | None = None,
                 on_delivered: Callable[[str], None] | None = None) -> None:
        self.settings = settings
        self.device_id = device_id
        self.topics = Topics(settings.prefix, device_id)
        self.software_version = software_version
        self._on_command = on_command or (lambda name, source, data=None, reply=None: None)
        self._seen_ids: deque[tuple[str, str]] = deque(maxlen=256)
        self._seen_lock = threading.Lock()
        self._say = Throttle(log)  # the lines a client makes the appliance repeat, one per message
        self.connected_event = threading.Event()
        self.subscribed_event = threading.Event()  # the broker confirmed the command subscriptions
        self.last_error: str | None = None
        self._appliance: ApplianceView | None = None  # set by build(): the daemon's clock for SPC summaries
        self.callback_errors = 0  # exceptions caught in paho callbacks (each one logged)
        client_id = settings.client_id or default_client_id(device_id, store.path)
        self.client_id = client_id
        self.connections = 0  # successful connections since start
        self._connected_at = 0.0  # monotonic time of the last one
        self._quick_drops = 0  # connections in a row the broker closed soon after they were made
        # clean session: the outbox, not the broker session, is what makes delivery durable
        self.v5 = settings.protocol == "5"
        if self.v5:
            self.client = _Client(CallbackAPIVersion.VERSION2, client_id=client_id, protocol=mqtt.MQTTv5)
        else:
            self.client = _Client(CallbackAPIVersion.VERSION2, client_id=client_id, clean_session=True)
        self.recipes: tuple[str, ...] = ()  # recipe names for Home Assistant's select (set by build)
        self._recipe_doc: dict[str, Any] = {"name": "none", "number": 0}
        self._part_doc: dict[str, Any] = {"part_id": ""}
        self._last_state: str | None = None  # the latest state message, published again at each connection
        self._state_lock = threading.Lock()  # the latest one is the last one published
        self.client.on_connect_error = self._on_connect_error
        self._last_logged_error: str | None = None
        self._configure_auth()
        self.client.will_set(self.topics.status, "offline", qos=1, retain=True)
        # the type hints say int, but paho only sleeps for these: sub-second backoff works
        self.client.reconnect_delay_set(settings.reconnect_min, settings.reconnect_max)  # type: ignore[arg-type]
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.on_publish = self._on_publish
        self.client.on_message = self._on_message
        self.client.on_subscribe = self._on_subscribe
        self.sender = OutboxSender(store, self._publish_kind, consumer=self.NAME, window=settings.window,
                                   resend_after=settings.resend_after, on_delivered=on_delivered)

    def _configure_auth(self) -> None:
        s = self.settings
        password = s.password
        if s.password_file:
            try:
                path = Path(s.password_file)
                password = path.read_text(encoding="utf-8").strip()
                if path.stat().st_mode & 0o004:
                    log.warning("MQTT: password_file %s is readable by every user (mode %o); "
                                "chmod 600 it", s.password_file, path.stat().st_mode & 0o777)
            except OSError as exc:
                raise ConfigError(f"[mqtt] password_file {s.password_file!r} cannot be read: {exc.strerror}") from None
        if s.username is not None:
            self.client.username_pw_set(s.username, password)
        if s.tls:
            try:
                self.client.tls_set(ca_certs=s.ca_file, certfile=s.cert_file, keyfile=s.key_file,
                                    cert_reqs=ssl.CERT_REQUIRED)
            except (OSError, ssl.SSLError, ValueError) as exc:
                raise ConfigError(f"[mqtt] TLS settings unusable: {exc}") from None
            if s.tls_insecure:
                self.client.tls_insecure_set(True)

    # --- lifecycle -------------------------------------------------------------------
    def start(self) -> None:
        """Start connecting (in the background; the broker may be down) and delivering."""
        self.sender.start()
        if self.v5:
            self.client.connect_async(self.settings.host, self.settings.port, keepalive=self.settings.keepalive,
                                      clean_start=True)
        else:
            self.client.connect_async(self.settings.host, self.settings.port, keepalive=self.settings.keepalive)
        self.client.loop_start()

    def stop(self, flush_timeout: float = 2.0) -> None:
        """Wait a little for in-flight results to be acknowledged, say offline, disconnect.

        Unacknowledged results stay in the outbox for the next start.
        """
        if self.connected_event.is_set():
            self.sender.wait_idle(flush_timeout)
            info = self.client.publish(self.topics.status, "offline", qos=1, retain=True)
            with contextlib.suppress(RuntimeError, ValueError):  # connection gone meanwhile: the last will says offline
                info.wait_for_publish(timeout=min(flush_timeout, 1.0))
        self.sender.stop()
        self.client.disconnect()
        self.client.loop_stop()

    @property
    def is_connected(self) -> bool:
        return self.connected_event.is_set() and self.network_thread_alive()

    def network_thread_alive(self) -> bool:
        """True while paho's network thread runs (after ``start``). paho keeps the thread in
        ``_thread`` and sets it to None when loop_forever ends, normally or by an exception."""
        thread = getattr(self.client, "_thread", None)
        return thread is not None and thread.is_alive()

    # --- publishing --------------------------------------------------------------------
    def _publish_kind(self, kind: str, payload: str) -> int:
        info = self.client.publish(self.topics.for_kind(kind), payload, qos=1, retain=False)
        if kind == "result":  # the outbox sends oldest first: the retained copy ends at the newest
            self.client.publish(self.topics.last_result, payload, qos=1, retain=True)
        return info.mid

    def publish_state(self, event: dict[str, Any]) -> None:
        """A sequencer event (retained: a new subscriber sees the current state). The latest is published again at
        each connection: one made while the broker was away (the daemon's first, at its start) is not lost."""
        with self._state_lock:
            self._last_state = json.dumps(event, default=str)
            self.client.publish(self.topics.state, self._last_state, qos=0, retain=True)

    def wake(self) -> None:
        """New outbox rows were stored."""
        self.sender.wake()

    # --- paho callbacks (network thread) -----------------------------------------------------
    @_never_raises
    def _on_connect(self, client, userdata, flags, reason_code, properties) -> None:
        if reason_code.is_failure:
            self.last_error = f"broker refused the connection: {reason_code}"
            if self.v5 and "protocol" in str(reason_code).lower():
                self.last_error += ' (a broker without MQTT 5: set [mqtt] protocol = "3.1.1")'
            log.warning("MQTT: %s", self.last_error)
            return
        self.last_error = None
        self._last_logged_error = None
        self.connections += 1
        self._connected_at = time.monotonic()
        log.info("MQTT connected to %s:%d", self.settings.host, self.settings.port)
        client.publish(self.topics.status, "online", qos=1, retain=True)
        client.subscribe([(self.topics.cmd_measure, 1), (self.topics.cmd_abort, 1), (self.topics.cmd_recipe, 1),
                          (self.topics.cmd_set, 1), (self.topics.cmd_part_id, 1)])
        client.publish(self.topics.recipe, json.dumps(self._recipe_doc), qos=1, retain=True)
        client.publish(self.topics.part_id, json.dumps(self._part_doc), qos=1, retain=True)
        with self._state_lock:
            if self._last_state is not None:
                client.publish(self.topics.state, self._last_state, qos=0, retain=True)
        if self.settings.home_assistant:
            for topic, config in discovery_messages(self.settings, self.topics, self.device_id, self.software_version,
                                                    self.recipes):
                client.publish(topic, json.dumps(config), qos=1, retain=True)
        self.connected_event.set()
        self.sender.connected()

    @_never_raises
    def _on_connect_error(self, exc: OSError) -> None:
        s = self.settings
        self.last_error = f"cannot connect to {s.host}:{s.port}: {type(exc).__name__}: {exc}"
        if self.last_error != self._last_logged_error:  # once per distinct cause, not at every retry
            self._last_logged_error = self.last_error
            log.warning("MQTT: %s (retrying every %g–%g s)", self.last_error, s.reconnect_min, s.reconnect_max)

    @_never_raises
    def _on_disconnect(self, client, userdata, flags, reason_code, properties) -> None:
        if self.connected_event.is_set():
            (log.warning if reason_code.is_failure else log.info)("MQTT disconnected: %s", reason_code)
            if reason_code.is_failure and time.monotonic() - self._connected_at < TAKEOVER_WINDOW:
                self._quick_drops += 1
                if self._quick_drops == TAKEOVER_DROPS:
                    self.last_error = (f"the broker closed the connection {TAKEOVER_DROPS} times in a row within "
                                       f"{TAKEOVER_WINDOW:g} s of connecting: another client uses the client id "
                                       f"{self.client_id!r} (two appliances with the same [device] id and "
                                       "[mqtt] client_id?)")
                    log.error("MQTT: %s", self.last_error)
            else:
                self._quick_drops = 0
        self.connected_event.clear()
        self.subscribed_event.clear()
        self.sender.disconnected()

    @_never_raises
    def _on_subscribe(self, client, userdata, mid, reason_codes, properties) -> None:
        if any(rc.is_failure for rc in reason_codes):
            self.last_error = f"broker refused the command subscriptions: {', '.join(map(str, reason_codes))}"
            log.warning("MQTT: %s", self.last_error)
            return
        self.subscribed_event.set()

    @_never_raises
    def _on_publish(self, client, userdata, mid, reason_code, properties) -> None:
        self.sender.acked(mid)

    @_never_raises
    def _on_message(self, client, userdata, message) -> None:
        name = self._command_name(message)
        if name is None:
            return
        doc, cmd_id = _command_document(message.payload)
        reply = self._replier(message, cmd_id)
        data, malformed = _command_data(name, message.payload, doc)
        if malformed is not None:
            self._say(logging.WARNING, "MQTT: %s refused: %s", message.topic, malformed)
            reply(CommandReply(name, "refused", "malformed", malformed))
            return
        if cmd_id is not None and self._seen_before(name, cmd_id):
            self._say(logging.INFO, "MQTT: duplicate %s command id %s ignored", name, cmd_id)
            reply(CommandReply(name, "refused", "duplicate"))
            return
        self._on_command(name, "mqtt", data or None, reply)

    def _command_name(self, message: Any) -> str | None:
        """The command a message on a command topic asks for; None for another topic, a retained message or
        an empty one (all said in the log but another topic's)."""
        if message.retain:
            self._say(logging.WARNING, "MQTT: ignoring retained command on %s (clear it with an empty retained message)", message.topic)
            return None
        name = self.topics.commands.get(message.topic)
        if name is None:
            return None
        if not message.payload:
            # how a retained command is cleared (the broker hands the empty message on to the subscribers
            # as a plain one): never a command itself
            self._say(logging.INFO, "MQTT: empty message on %s ignored (the clearing of a retained command)", message.topic)
            return None
        return name

    def _seen_before(self, name: str, cmd_id: str) -> bool:
        """Whether a command of this name and id came already (else it is remembered)."""
        with self._seen_lock:
            if (name, cmd_id) in self._seen_ids:
                return True
            self._seen_ids.append((name, cmd_id))
            return False

    def _replier(self, message: Any, cmd_id: str | None) -> Callable[[CommandReply], None]:
        """The reply of a command message: to its MQTT 5 response topic with its correlation data, else to
        the ``reply`` topic with its id (any thread; publishing never blocks)."""
        props = getattr(message, "properties", None)
        topic = getattr(props, "ResponseTopic", None) if props is not None else None
        correlation = getattr(props, "CorrelationData", None) if props is not None else None
        if not isinstance(topic, str) or not topic or any(ch in topic for ch in "#+\0"):
            topic = self.topics.reply  # none, or one no PUBLISH may name
        elif not (topic == self.topics.reply or topic.startswith(self.topics.reply + "/")) or len(topic) > MAX_TOPIC:
            # replies go where the appliance decides: a response topic naming cmd/measure would fire the solenoid
            self._say(logging.WARNING, "MQTT: response topic %r refused (only under %s/); replying there",
                      topic[:MAX_TOPIC], self.topics.reply)
            topic = self.topics.reply
        if isinstance(correlation, (bytes, bytearray)) and len(correlation) > MAX_CORRELATION:
            self._say(logging.WARNING, "MQTT: correlation data of %d bytes dropped (at most %d)", len(correlation),
                      MAX_CORRELATION)
            correlation = None
        command = message.topic.rsplit("/", 1)[-1]

        def reply(r: CommandReply) -> None:
            doc = r.to_dict() | {"command": command, "id": cmd_id, "device_id": self.device_id,
                                 "timestamp": self._appliance.now() if self._appliance is not None else time.time()}
            properties = None
            if self.v5 and correlation is not None:
                properties = Properties(PacketTypes.PUBLISH)
                properties.CorrelationData = correlation
            self.client.publish(topic, json.dumps(doc, allow_nan=False, default=str), qos=1, properties=properties)

        return reply

    # --- the publisher port ---------------------------------------------------------
    NAME = "mqtt"
    OUTBOX = ("result",)  # every result is queued in the store's outbox with it, delivered from there

    @classmethod
    def build(cls, settings: MqttSettings, appliance: ApplianceView) -> "MqttService":
        store = appliance.store
        assert store is not None, "the store opens before the publishers"
        service = cls(settings, appliance.config.device_id, store, software_version=appliance.software_version,
                      on_command=appliance.command)
        service._appliance = appliance
        service.recipes = tuple(r.name for r in appliance.parts.book.recipes)
        service._set_recipe_doc(appliance.parts.recipe)
        service._part_doc = {"part_id": appliance.parts.part_id or ""}
        return service

    def _set_recipe_doc(self, recipe: Any) -> None:
        self._recipe_doc = {"name": recipe.name, "number": recipe.number} if recipe else {"name": "none", "number": 0}

    def on_recipe(self, recipe: Any) -> None:
        self._set_recipe_doc(recipe)
        self.publish_retained(self.topics.recipe, self._recipe_doc)

    def on_part_id(self, part_id: str | None) -> None:
        self._part_doc = {"part_id": part_id or ""}
        self.publish_retained(self.topics.part_id, self._part_doc)

    def failure(self) -> str | None:
        if self.sender.error is not None:
            return f"the MQTT outbox sender failed: {self.sender.error}"
        if not self.network_thread_alive():
            # commands and acknowledgements are no longer read: stop feeding the watchdog and let
            # systemd restart the daemon (the outbox keeps every unacknowledged result)
            return "the MQTT network thread stopped"
        return None

    def where(self) -> str:
        return f"MQTT {self.settings.host}:{self.settings.port}"

    def health(self) -> dict[str, Any]:
        store = self.sender.store
        return {"broker": f"{self.settings.host}:{self.settings.port}", "connected": self.is_connected,
                "outbox_backlog": store.outbox_count(self.NAME) if store is not None else None}

    def live_fields(self) -> dict[str, Any]:
        return {"mqtt_connected": self.is_connected, "outbox_pending": self.sender.pending}

    def status(self) -> list[str]:
        out = ["mqtt connected" if self.is_connected else
               "mqtt disconnected" + (f" ({self.last_error})" if self.last_error else "")]
        if self.sender.pending:
            out.append(f"{self.sender.pending} result(s) waiting for the broker")
        return out

    def on_state(self, message: Mapping[str, Any], event: Any) -> None:
        self.publish_state(dict(message))

    def on_result(self, stored: Any, measurement: Any) -> None:
        self.wake()

    def on_set(self, progress: Mapping[str, Any]) -> None:
        self.publish_retained(self.topics.set_state, dict(progress))

    def on_tensor_set(self, record: Mapping[str, Any]) -> None:
        # retained: the latest complete tensor (an aborted or failed set shows on the `set` topic)
        if record.get("status") == "complete":
            self.publish_retained(self.topics.tensor, dict(record))

    def on_part_done(self, recipe: Any) -> None:
        """The retained SPC summary of the recipe's latest parts."""
        from service.parts.recipes import SPC_WINDOW, recipe_spc

        app = self._appliance
        store = self.sender.store
        if app is None or store is None:
            return
        spc = recipe_spc(store, recipe.name, limit=SPC_WINDOW)
        doc: dict[str, Any] = {"recipe": recipe.name, "version": recipe.version, "window": SPC_WINDOW,
                               "device_id": self.device_id, "timestamp": app.now()}
        if spc is None:
            doc["status"] = "fewer than 2 usable parts"
        else:
            doc |= spc.to_dict() | {"recipe": recipe.name, "status": "ok"}
        self.publish_retained(self.topics.spc(recipe.name), doc)

    def publish_retained(self, topic: str, doc: dict[str, Any]) -> None:
        """A retained JSON document (QoS 1), e.g. the SPC summary of a recipe or the latest tensor. While
        the broker is away paho keeps it queued and sends it on reconnection (a test holds this); a
        restart of the daemon in between loses it until the next one is published."""
        self.client.publish(topic, json.dumps(doc, allow_nan=False, default=str), qos=1, retain=True)


PUBLISHER = MqttService
