"""Delivery from the durable outbox: publish what the store holds until the broker acknowledges it.

The outbox rows live in the result store (``Store.outbox_*``), written in the
same transaction as the measurement, one row per consumer: each publisher that
delivers from the outbox (``Publisher.OUTBOX``) names its rows by its ``NAME``
and runs its own ``OutboxSender`` over them, so MQTT and Sparkplug acknowledge
and resend independently. ``OutboxSender`` runs one thread that

* hands its consumer's pending rows to the client while it may publish (at most
  ``window`` unacknowledged at a time, oldest first),
* deletes a row when the broker acknowledges its publication (QoS 1 PUBACK,
  reported by paho's ``on_publish``),
* sends a row again if no acknowledgement came within ``resend_after``
  seconds of being connected (paho itself re-sends its in-flight messages after
  a reconnect; this covers anything it dropped).

A row can therefore reach the broker more than once (acknowledgement lost,
daemon killed between PUBACK and the delete); consumers dedupe by the
payload's ``uuid``. A row is never lost: it leaves the database only after a
PUBACK for one of its publications.

A store that cannot be written (a full disk) does not stop the sender: the
attempt counter is bookkeeping and is skipped, and a row whose PUBACK came but
whose delete failed is remembered as delivered (not sent again) and deleted
once the store takes writes again. Only a damaged store stops it.

Thread rules: paho calls ``acked``/``connected``/``disconnected`` from its
network thread while holding its own locks, so those only enqueue and set an
event; every store access and every publish happens in the sender's thread.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from dataclasses import dataclass
from typing import Callable

from service.errors import StoreDamaged, StoreError

from .store import Store

log = logging.getLogger("moi.outbox")

#: publish(kind, payload_text) -> message id (paho mid)
PublishFn = Callable[[str, str], int]


@dataclass
class _InFlight:
    item_id: int
    uuid: str
    mid: int
    sent_at: float  # monotonic s


class OutboxSender:
    """Moves outbox rows to the broker. Start with ``start()``, stop with ``stop()``."""

    def __init__(self, store: Store, publish: PublishFn, *, consumer: str, window: int = 10, resend_after: float = 30.0,
                 clock: Callable[[], float] = time.monotonic,
                 on_delivered: Callable[[str], None] | None = None) -> None:
        self.store = store
        self.consumer = consumer  # the publisher whose rows these are (``Publisher.NAME``)
        self._publish = publish
        self.window = window
        self.resend_after = resend_after
        self._clock = clock
        self._on_delivered = on_delivered or (lambda uuid: None)
        self._acks: queue.SimpleQueue[int] = queue.SimpleQueue()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._inflight: dict[int, _InFlight] = {}  # item id → in flight
        self._by_mid: dict[int, int] = {}           # mid → item id
        self._delivered: dict[int, str] = {}        # item id → uuid: acknowledged, its delete not yet written
        self._write_logged = False
        self._idle = threading.Condition()
        self._thread: threading.Thread | None = None
        self.pending = store.outbox_count(consumer)  # rows not yet acknowledged (updated by the sender thread)
        self.error: BaseException | None = None

    # --- called from other threads (must not block) ----------------------------------
    def wake(self) -> None:
        """New rows were stored: look at the outbox now."""
        self._wake.set()

    def acked(self, mid: int) -> None:
        self._acks.put(mid)
        self._wake.set()

    def connected(self) -> None:
        self._connected.set()
        self._wake.set()

    def disconnected(self) -> None:
        self._connected.clear()
        self._wake.set()

    @property
    def is_connected(self) -> bool:
        return self._connected.is_set()

    # --- lifecycle -----------------------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=f"moi-outbox-{self.consumer}", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def wait_idle(self, timeout: float) -> bool:
        """Wait until nothing is in flight (all handed rows acknowledged). True if so."""
        deadline = time.monotonic() + timeout
        with self._idle:
            while self._inflight:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._idle.wait(left)
        return True

    def wait_empty(self, timeout: float) -> bool:
        """Wait until the outbox is empty (everything acknowledged). True if so."""
        deadline = time.monotonic() + timeout
        with self._idle:
            while self.pending or self._inflight:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._idle.wait(min(left, 0.5))
        return True

    # --- the sender thread -------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._wake.wait(timeout=1.0)
                self._wake.clear()
                self._step()
            self._drain_acks()  # acknowledgements that arrived while stopping still count
        except BaseException as exc:  # reported to the daemon, whose main loop turns it into a fault
            self.error = exc
            log.exception("outbox sender (%s) stopped", self.consumer)
            raise

    def _drain_acks(self) -> None:
        while True:
            try:
                mid = self._acks.get_nowait()
            except queue.Empty:
                break
            item_id = self._by_mid.pop(mid, None)
            if item_id is None:
                continue  # status/state/discovery messages, or a superseded resend
            fl = self._inflight.pop(item_id, None)
            # drop the other mids of this row (an earlier send that paho may still retry)
            for m in [m for m, i in self._by_mid.items() if i == item_id]:
                del self._by_mid[m]
            self._delivered[item_id] = fl.uuid if fl is not None else ""
        for item_id, uuid in list(self._delivered.items()):
            try:
                removed = self.store.outbox_ack(item_id)
            except StoreDamaged:
                raise
            except StoreError as exc:
                self._write_failed(exc)
                return  # the rows stay acknowledged in memory; the next step tries again
            del self._delivered[item_id]
            if removed and uuid:
                self._on_delivered(uuid)

    def _write_failed(self, exc: StoreError) -> None:
        if not self._write_logged:  # once per episode: a full disk fails every step
            log.error("outbox: %s; results go on being published, their bookkeeping waits for space", exc)
            self._write_logged = True

    def _step(self) -> None:
        self._drain_acks()
        if self._connected.is_set():
            now = self._clock()
            for fl in list(self._inflight.values()):
                if now - fl.sent_at > self.resend_after:
                    item = next((i for i in self.store.outbox_pending(self.consumer, limit=self.window + len(self._inflight))
                                 if i.id == fl.item_id), None)
                    if item is None:  # acknowledged meanwhile through another path
                        self._inflight.pop(fl.item_id, None)
                        continue
                    log.info("outbox: no acknowledgement for %s after %.0f s; sending again", fl.uuid, now - fl.sent_at)
                    self._send(item.id, item.uuid, item.kind, item.payload)
            free = self.window - len(self._inflight)
            if free > 0:
                for item in self.store.outbox_pending(self.consumer, limit=free, exclude=[*self._inflight, *self._delivered]):
                    if not self._connected.is_set():
                        break
                    self._send(item.id, item.uuid, item.kind, item.payload)
        self.pending = self.store.outbox_count(self.consumer) - len(self._delivered)
        if self.store.write_failure is None:
            self._write_logged = False
        with self._idle:
            self._idle.notify_all()

    def _send(self, item_id: int, uuid: str, kind: str, payload: str) -> None:
        mid = self._publish(kind, payload)
        self._by_mid[mid] = item_id
        self._inflight[item_id] = _InFlight(item_id, uuid, mid, self._clock())
        try:
            self.store.outbox_attempt(item_id)
        except StoreDamaged:
            raise
        except StoreError as exc:
            self._write_failed(exc)
