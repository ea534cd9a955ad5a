"""The Sparkplug B edge node: the appliance as one device on the plant's SCADA broker.

Session (Sparkplug B 3.0):

* every MQTT connection carries an NDEATH last will with the birth/death sequence number ``bdSeq``;
  the next connection's is one more (0–255, kept in the state directory across restarts);
* once connected, and once the configured primary host's STATE says online (at once without one), the
  node publishes NBIRTH (seq 0, bdSeq, ``Node Control/Rebirth``) and DBIRTH (every device metric with
  its alias, data type and ``engUnit``; ``service.publish.sparkplug.metrics``); every later message of
  the node carries the next ``seq`` (0–255);
* each result is one DDATA (metrics by alias, each with its data type), delivered from the durable outbox (consumer
  ``sparkplug``): published with QoS 1 and dropped from the outbox on the broker's PUBACK, so a result
  survives a broker restart, a power cut or a host that is away; a result held back while no birth was
  valid is flagged historical. A result may arrive twice (a PUBACK lost): hosts dedupe by
  ``Result/UUID``. (The specification asks QoS 0 for DDATA; a result that may not be lost needs the
  acknowledgement.)
* the live state (``Status/*``) is a DDATA when it changes;
* NCMD ``Node Control/Rebirth`` = true: NBIRTH and DBIRTH again, at most one pair per ``rebirth_interval``
  (``service.publish.sparkplug.rebirth``: requests within it get one birth at its end); DCMD ``Command/Measure``,
  ``Command/Abort``, ``Command/Recipe``, ``Command/Part ID`` are the MQTT commands, answered the same
  way (``Command/Reply`` carries the JSON an MQTT reply carries); a malformed NCMD or DCMD is answered
  (a reply, or a log line for the node) and otherwise ignored;
* the primary host's STATE is untrusted input (``service.publish.sparkplug.host_state``): one that is not the
  specification's JSON, or stamped beyond this clock plus ``state_tolerance``, is refused and logged;
* when the primary host's STATE turns offline, the node stops sending, publishes NDEATH, disconnects
  and connects again with the next bdSeq, then waits for the host to be online.

Thread rules as in ``service.publish.mqtt.client``: paho's callbacks only decode, enqueue and set
events; one lock keeps ``seq`` and the order of the node's messages.
"""

from __future__ import annotations

import contextlib
import json
import logging
import queue
import threading
import time
from pathlib import Path
from typing import Any, Callable

import paho.mqtt.client as mqtt
from google.protobuf.message import DecodeError
from paho.mqtt.enums import CallbackAPIVersion

from service.errors import HostStateRefused
from service.logs import Throttle
from service.persistence.outbox import OutboxSender
from service.persistence.store import Store
from service.publish.callbacks import never_raises
from service.publish.port import ApplianceView, Publisher
from service.publish.replies import CommandReply

from . import metrics as M
from .host_state import read_state
from .payload import VALUE_FIELD, DataType, Payload, add_metric, get_value, now_ms, state_topic, topic
from .rebirth import BirthLimit
from .settings import SparkplugSettings

log = logging.getLogger("moi.sparkplug")

#: where the last bdSeq is kept in the state directory (a restart's NBIRTH must not repeat it)
BDSEQ_FILE = "sparkplug-bdseq"
#: a command payload larger than this is malformed (no command of the appliance needs more)
MAX_COMMAND_BYTES = 4096


_never_raises = never_raises(log, "Sparkplug")


class SparkplugNode(Publisher):
    """The edge node (a publisher of the port). ``on_command(name, source, data, reply)`` as for MQTT."""

    NAME = "sparkplug"
    OUTBOX = ("result",)

    def __init__(self, settings: SparkplugSettings, device_id: str, store: Store, *, software_version: str = "",
                 on_command: Callable[..., None] | None = None) -> None:
        self.settings = settings
        self.device = device_id
        self.edge = settings.edge_node_id or device_id
        self.group = settings.group_id
        self.software_version = software_version
        self._on_command = on_command or (lambda name, source, data=None, reply=None: None)
        self._bdseq_path = Path(store.state_dir) / BDSEQ_FILE
        self._bdseq = self._next_bdseq()
        self._lock = threading.RLock()  # seq and the order of the node's messages
        self._seq = 0
        self._born = False
        self._birth_ms = 0
        self.births = 0  # NBIRTHs published since start
        self._host_online = settings.primary_host is None
        self._host_stamp = -1  # the timestamp of the newest STATE acted on
        self._limit = BirthLimit(settings.rebirth_interval)  # read and changed under _lock
        self._say = Throttle(log)  # the lines a broker client can make the node repeat
        self._live: tuple[Any, ...] | None = None
        self._last_result: dict[str, Any] = {}
        self.callback_errors = 0
        self.states_refused = 0  # STATE messages of the primary host not acted on (malformed, stamped ahead)
        self.last_error: str | None = None
        self.connected_event = threading.Event()
        self.born_event = threading.Event()
        self._control: queue.SimpleQueue[str] = queue.SimpleQueue()
        self._control_thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=settings.client_id or f"moi-sparkplug-{self.edge}",
                                  clean_session=True)
        self.client.reconnect_delay_set(settings.reconnect_min, settings.reconnect_max)  # type: ignore[arg-type]
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.on_publish = self._on_publish
        self.client.on_message = self._on_message
        self._set_will()
        self.sender = OutboxSender(store, self._publish_result, consumer=self.NAME, window=settings.window,
                                   resend_after=settings.resend_after)

    # --- topics ----------------------------------------------------------------------------------
    def topic(self, message_type: str, device: bool = False) -> str:
        return topic(self.group, message_type, self.edge, self.device if device else None)

    # --- bdSeq -----------------------------------------------------------------------------------
    def _next_bdseq(self) -> int:
        """One more than the last connection's (kept across restarts), 0–255."""
        try:
            last = int(self._bdseq_path.read_text().strip())
        except (OSError, ValueError):
            last = -1
        value = (last + 1) % 256
        try:
            self._bdseq_path.write_text(f"{value}\n")
        except OSError as exc:  # the store's own writes report a full disk; the session goes on
            log.warning("Sparkplug: cannot keep bdSeq in %s: %s", self._bdseq_path, exc.strerror)
        return value

    def _death(self) -> bytes:
        p = Payload(timestamp=now_ms())
        add_metric(p, M.BD_SEQ, DataType.Int64, self._bdseq)
        return p.SerializeToString()

    def _set_will(self) -> None:
        self.client.will_set(self.topic("NDEATH"), self._death(), qos=1, retain=False)

    # --- lifecycle -------------------------------------------------------------------------------
    def start(self) -> None:
        self.sender.start()
        self._control_thread = threading.Thread(target=self._control_loop, name="moi-sparkplug", daemon=True)
        self._control_thread.start()
        self._connect()

    def _connect(self) -> None:
        self.client.connect_async(self.settings.host, self.settings.port, keepalive=self.settings.keepalive)
        self.client.loop_start()

    def stop(self, flush_timeout: float = 2.0) -> None:
        """Wait a little for results in flight, publish NDEATH (a clean disconnect sends no will), disconnect."""
        if self._stopping.is_set():
            return
        self._stopping.set()
        self._control.put("stop")
        if self.connected_event.is_set():
            self.sender.wait_idle(flush_timeout)
            self._publish_death(min(flush_timeout, 1.0))
        self.sender.stop()
        self.client.disconnect()
        self.client.loop_stop()
        if self._control_thread is not None:
            self._control_thread.join(5)

    def _publish_death(self, timeout: float) -> None:
        with self._lock:
            self._born = False
            self.born_event.clear()
            info = self.client.publish(self.topic("NDEATH"), self._death(), qos=1)
        # the connection may go meanwhile: the broker sends the will instead
        with contextlib.suppress(RuntimeError, ValueError):
            info.wait_for_publish(timeout=timeout)

    def _control_loop(self) -> None:
        """Work that may not run in paho's thread: leaving the session when the primary host goes away; the
        births that Rebirth requests ask for, at most one per ``rebirth_interval``."""
        while True:
            with self._lock:
                due = self._limit.due_in()
            try:
                what = self._control.get(timeout=due)
            except queue.Empty:
                what = "rebirth due"
            if what == "stop":
                return
            if what in ("rebirth", "rebirth due"):
                self._rebirth(what)
            elif what == "host offline" and not self._stopping.is_set():
                log.info("Sparkplug: primary host %s offline: NDEATH, reconnecting to wait for it",
                         self.settings.primary_host)
                self.sender.disconnected()
                self._publish_death(1.0)
                self.client.disconnect()
                self.client.loop_stop()
                if not self._stopping.is_set():
                    self._connect()

    # --- births ------------------------------------------------------------------------------------
    def _rebirth(self, what: str) -> None:
        with self._lock:  # one step for a thread that reads the limit under the lock: the birth and its answer
            if (what == "rebirth due" or self._limit.request()) and self._born:
                self._birth()  # its ``born()`` answers every request so far
            if what == "rebirth due":
                self._limit.forget()  # answered; or no session to birth again: the next birth answers it

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (self._seq + 1) % 256
        return seq

    def _birth(self) -> None:
        """NBIRTH (seq 0) and DBIRTH with every metric; then results may go out."""
        with self._lock:
            if not self.connected_event.is_set():
                return
            ts = now_ms()
            self._seq = 0
            nb = Payload(timestamp=ts, seq=self._next_seq())
            add_metric(nb, M.BD_SEQ, DataType.Int64, self._bdseq)
            add_metric(nb, M.REBIRTH, DataType.Boolean, False, alias=M.ALIAS[M.REBIRTH])
            add_metric(nb, M.SOFTWARE_VERSION, DataType.String, self.software_version, alias=M.ALIAS[M.SOFTWARE_VERSION])
            self.client.publish(self.topic("NBIRTH"), nb.SerializeToString(), qos=0)
            db = Payload(timestamp=ts, seq=self._next_seq())
            live = dict(zip((m.name for m in M.LIVE), self._live or (None,) * len(M.LIVE)))
            for m in M.DEVICE:
                value = self._last_result.get(m.name, live.get(m.name))
                if m.name in M.COMMANDS and m.datatype == DataType.Boolean:
                    value = False
                add_metric(db, m.name, m.datatype, value, alias=M.ALIAS[m.name], unit=m.unit, timestamp=ts)
            self.client.publish(self.topic("DBIRTH", device=True), db.SerializeToString(), qos=0)
            self._born = True
            self._birth_ms = ts
            self.births += 1
            self._limit.born()
            self.born_event.set()
        log.info("Sparkplug: NBIRTH/DBIRTH %s/%s/%s (bdSeq %d)", self.group, self.edge, self.device, self._bdseq)
        self.sender.connected()

    def _data(self, values: list[tuple[M.DeviceMetric, Any]], *, qos: int = 0, timestamp: int | None = None,
              historical: bool = False) -> int | None:
        """One DDATA of ``values`` by alias; its message id, or None while no birth is valid."""
        with self._lock:
            if not self._born:
                return None
            p = Payload(timestamp=now_ms(), seq=self._next_seq())
            for m, value in values:
                # with its data type, which the specification makes optional after the birth: Tahu's JavaScript
                # codec (what Node.js hosts decode with) reads no value without it
                add_metric(p, None, m.datatype, value, alias=M.ALIAS[m.name], timestamp=timestamp,
                           historical=historical)
            return self.client.publish(self.topic("DDATA", device=True), p.SerializeToString(), qos=qos).mid

    # --- results (the outbox sender's thread) ----------------------------------------------------------
    def _publish_result(self, kind: str, payload_text: str) -> int:
        if kind != "result":
            raise ValueError(f"unknown outbox kind {kind!r} for Sparkplug")
        payload = json.loads(payload_text)
        values = [(m, m.read(payload) if m.read is not None else None) for m in M.RESULT]
        ts = M.finished_ms(payload)
        historical = ts is not None and ts < self._birth_ms
        mid = self._data(values, qos=1, timestamp=ts, historical=historical)
        if mid is None:
            # the birth went (host offline, connection lost) between the sender's check and here: the row
            # stays in flight and goes again after resend_after, once a birth is valid
            return -1
        self._last_result = {m.name: v for m, v in values}
        return mid

    def wake(self) -> None:
        self.sender.wake()

    # --- paho callbacks (network thread) -----------------------------------------------------------
    @_never_raises
    def _on_connect(self, client, userdata, flags, reason_code, properties) -> None:
        if reason_code.is_failure:
            self.last_error = f"broker refused the connection: {reason_code}"
            log.warning("Sparkplug: %s", self.last_error)
            return
        self.last_error = None
        self.connected_event.set()
        subs = [(self.topic("NCMD"), 1), (self.topic("DCMD", device=True), 1)]
        if self.settings.primary_host is not None:
            self._host_online = False  # until its STATE (retained) says otherwise
            subs.append((state_topic(self.settings.primary_host), 1))
        client.subscribe(subs)
        log.info("Sparkplug connected to %s:%d (bdSeq %d)", self.settings.host, self.settings.port, self._bdseq)
        if self._host_online:
            self._birth()

    @_never_raises
    def _on_disconnect(self, client, userdata, flags, reason_code, properties) -> None:
        with self._lock:
            self._born = False
            self.born_event.clear()
        if self.connected_event.is_set():
            log.info("Sparkplug disconnected: %s", reason_code)
        self.connected_event.clear()
        self.sender.disconnected()
        if not self._stopping.is_set():
            # the next connection is a new session: its will carries the next bdSeq, and so will its NBIRTH
            self._bdseq = self._next_bdseq()
            self._set_will()

    @_never_raises
    def _on_publish(self, client, userdata, mid, reason_code, properties) -> None:
        self.sender.acked(mid)

    @_never_raises
    def _on_message(self, client, userdata, message) -> None:
        if self.settings.primary_host is not None and message.topic == state_topic(self.settings.primary_host):
            return self._on_state(message.payload)
        if message.topic == self.topic("NCMD"):
            return self._on_ncmd(message.payload)
        if message.topic == self.topic("DCMD", device=True):
            return self._on_dcmd(message.payload)

    # --- the primary host -------------------------------------------------------------------------------
    def _on_state(self, raw: bytes) -> None:
        try:
            state = read_state(raw, now_ms(), int(self.settings.state_tolerance * 1000))
        except HostStateRefused as exc:
            self.states_refused += 1
            self._say(logging.WARNING, "Sparkplug: STATE of %s refused: %s", self.settings.primary_host, exc)
            return
        online, stamp = state.online, state.timestamp
        if stamp < self._host_stamp:
            return  # an older session's STATE, delivered late
        self._host_stamp = stamp
        was, self._host_online = self._host_online, online
        if online and not self._born:
            self._birth()
        elif not online and was:
            self._control.put("host offline")

    # --- commands -------------------------------------------------------------------------------------------
    def _decode(self, raw: bytes, what: str) -> Any | None:
        if len(raw) > MAX_COMMAND_BYTES:
            log.warning("Sparkplug: %s of %d bytes ignored (at most %d)", what, len(raw), MAX_COMMAND_BYTES)
            return None
        try:
            return Payload.FromString(raw)
        except (DecodeError, RuntimeError, ValueError) as exc:
            log.warning("Sparkplug: malformed %s ignored: %s", what, exc)
            return None

    def _on_ncmd(self, raw: bytes) -> None:
        p = self._decode(raw, "NCMD")
        if p is None:
            return
        for metric in p.metrics:
            name = metric.name or M.BY_ALIAS.get(metric.alias, "")
            if name == M.REBIRTH:
                if get_value(metric, DataType.Boolean) is True:
                    self._say(logging.INFO, "Sparkplug: rebirth requested")
                    self._control.put("rebirth")
                else:
                    log.warning("Sparkplug: NCMD %s without the boolean true ignored", M.REBIRTH)
            else:
                log.warning("Sparkplug: NCMD of unknown metric %r ignored (the node takes %s)", name, M.REBIRTH)

    def _on_dcmd(self, raw: bytes) -> None:
        p = self._decode(raw, "DCMD")
        if p is None:
            return self._reply(CommandReply("unknown", "refused", "malformed", "not a Sparkplug B payload"))
        for metric in p.metrics:
            name = metric.name or M.BY_ALIAS.get(metric.alias, "")
            entry = M.COMMANDS.get(name)
            if entry is None:
                self._reply(CommandReply(name or "unknown", "refused", "unknown_command",
                                         f"writable metrics: {', '.join(M.COMMANDS)}"))
                continue
            spec, command = entry
            which = metric.WhichOneof("value")
            if which != VALUE_FIELD[spec.datatype] or metric.is_null:
                self._reply(CommandReply(command, "refused", "malformed", f"{name} takes a {spec.datatype.name} value"))
                continue
            value = get_value(metric, spec.datatype)
            if spec.datatype == DataType.Boolean:
                if value is not True:
                    continue  # writing false is how a host resets the button: nothing to do
                self._on_command(command, "sparkplug", None, self._reply)
            else:
                self._on_command(command, "sparkplug", {command: value}, self._reply)

    def _reply(self, reply: CommandReply) -> None:
        """A command's outcome as ``Command/Reply`` (any thread)."""
        doc = json.dumps(reply.to_dict() | {"device_id": self.device, "timestamp": time.time()},
                         allow_nan=False, default=str)
        if self._data([(M.REPLY, doc)]) is None:
            log.info("Sparkplug: reply %s not sent (no birth is valid)", doc)

    # --- the publisher port ---------------------------------------------------------------------------
    @classmethod
    def build(cls, settings: SparkplugSettings, appliance: ApplianceView) -> "SparkplugNode":
        store = appliance.store
        assert store is not None, "the store opens before the publishers"
        return cls(settings, appliance.config.device_id, store, software_version=appliance.software_version,
                   on_command=appliance.command)

    def on_result(self, stored: Any, measurement: Any) -> None:
        self.sender.wake()

    def on_live(self, live: Any) -> None:
        now = (live.state, bool(live.busy), bool(live.fault))
        if now == self._live:
            return
        self._live = now
        self._data(list(zip(M.LIVE, now)))

    def failure(self) -> str | None:
        if self.sender.error is not None:
            return f"the Sparkplug outbox sender failed: {self.sender.error}"
        return None

    def where(self) -> str:
        return f"Sparkplug {self.settings.host}:{self.settings.port} as {self.group}/{self.edge}/{self.device}"

    def health(self) -> dict[str, Any]:
        return {"broker": f"{self.settings.host}:{self.settings.port}", "connected": self.connected_event.is_set(),
                "born": self.born_event.is_set(), "primary_host_online": self._host_online,
                "bdSeq": self._bdseq, "outbox_backlog": self.sender.pending, "births": self.births,
                "rebirth_requests": self._limit.requests, "states_refused": self.states_refused}

    def status(self) -> list[str]:
        if self.born_event.is_set():
            return ["sparkplug born"]
        if self.connected_event.is_set():
            return [f"sparkplug waiting for host {self.settings.primary_host}"]
        return ["sparkplug disconnected" + (f" ({self.last_error})" if self.last_error else "")]

PUBLISHER = SparkplugNode
