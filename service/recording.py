"""The daemon's results: each run of the sequencer stored once, with what it came to for its part, then handed to
every publisher (main loop thread).

The sequencer's result sink (``Recorder.sink``) judges the result for its part (``service.parts``: the part
tracker, the calibration rule, the tensor set's desk), stores the measurement and its outbox rows in one SQLite
transaction (one record envelope: who measured, with what, when, on which rig and configuration, for which part),
then hands the stored result to every publisher: nothing is published before the store has it. A run that ends in
FAULT or is aborted is stored too, as is a captured one whose result could not be stored (its trace is the
evidence). Whoever triggered the run hears how it ended.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections import deque
from typing import Any, Mapping

from firmware_host import Event, Measurement, State
from firmware_host.errors import fault_words
from measurement import IdentificationResult, Rig
from measurement import flags as F
from service.core import vocabulary as V
from service.parts import calibration as calibration_rule
from service.parts.outcome import PartOutcome
from service.parts.recipes import Recipe
from service.publish.payload import result_payload
from service.publish.replies import CommandReply, ReplyTo

from . import __version__
from .errors import ServiceError, StoreError

log = logging.getLogger("moi.daemon")


class Recorder:
    """The runs of one appliance (``service.daemon.Appliance``: its store, configuration, parts, tensor set desk,
    publishers and clocks), from ARMED to stored. ``stored``: the UUIDs stored since start (ok, failed, aborted),
    in order."""

    def __init__(self, app: Any) -> None:
        self.app = app
        # measurement id → (monotonic time of ARMED, trigger source): a run's start is the wall clock at its end
        # less the monotonic time it took, so a step of the wall clock never gives a negative duration
        self._started: dict[str, tuple[float, str]] = {}
        self._reply: dict[str, ReplyTo] = {}  # measurement id → who hears its outcome
        self._part: dict[str, tuple[str | None, Recipe | None]] = {}  # measurement id → its part ID and recipe
        self.stored: list[str] = []
        self._durable: deque[str] = deque(maxlen=16)  # UUIDs of the latest results the store holds
        self._cond = threading.Condition()

    def armed(self, uuid: str, source: str, reply: ReplyTo | None, part: tuple[str | None, Recipe | None]) -> None:
        """A run started (ARMED): who started it, who hears its outcome, the part and recipe it measures."""
        self._started[uuid] = (time.monotonic(), source)
        if reply is not None:
            self._reply[uuid] = reply
        self._part[uuid] = part

    def running(self, uuid: str | None) -> bool:
        return uuid is not None and uuid in self._started

    def durable(self, uuid: str | None) -> bool:
        """Whether the store holds this run's result (one of the latest)."""
        return uuid in self._durable

    def _record(self, uuid: str, status: str, trigger: str, started: float, finished: float,
                outcome: PartOutcome, rig: Rig | None = None, **rest: Any) -> Any:
        """Store one measurement (``Store.record``) with what every row carries: who measured (the door that
        started it and its operator: the web user who pressed Measure, else the door), with what, when, on which
        rig and configuration, for which part; ``rest``: the result, its trace, its payload."""
        store, cfg = self.app.store, self.app.config
        assert store is not None
        return store.record(uuid=uuid, status=status, trigger=trigger, operator=V.operator_of(trigger),
                            device_id=cfg.device_id,
                            software_version=__version__, started_at=started, finished_at=finished,
                            rig=(rig or cfg.rig).to_dict(), config=cfg.to_dict(), part=outcome.store_columns(),
                            **rest)

    def sink(self, m: Measurement) -> None:
        """The sequencer's result sink: store (with the outbox row), then Modbus, then wake MQTT. Whatever fails
        before the row is written (judging, a lazy import, no descriptor left), a failed row keeps the trace and
        the failure; the error goes on to the sequencer, whose FAULT the PLC and MQTT see."""
        try:
            self._store_result(m)
        except BaseException as exc:
            if m.id not in self._durable:
                self._store_lost(m, exc)
            raise

    def _store_lost(self, m: Measurement, exc: BaseException) -> None:
        """A captured measurement whose result could not be stored: a failed row with its trace (always, it is
        the evidence) and what went wrong."""
        finished = self.app.wall_clock()
        self._started.pop(m.id, None)
        part_id, recipe = self._part.pop(m.id, (self.app.parts.part_id, self.app.parts.recipe))
        error = f"captured, but not stored as a result: {fault_words(exc)}"
        if (reply := self._reply.pop(m.id, None)) is not None:
            reply(CommandReply("trigger", "failed", "measurement_failed", error, {"uuid": m.id}))
        try:
            result = m.result.to_dict()
        except Exception:
            result = None
        try:
            self._record(m.id, "failed", m.requested_by, finished - (m.finished_at - m.requested_at) / self.app.clock_scale(),
                         finished, _unjudged(part_id, recipe), error=error, result=result, trace_t=m.trace.t,
                         trace_angle=m.trace.angle, trace_meta=dict(m.trace.meta))
        except BaseException:
            log.exception("could not store the failed measurement %s either", m.id)
            return
        log.error("measurement %s stored as failed: %s", m.id, error)
        self._note_stored(m.id)

    def _store_result(self, m: Measurement) -> None:
        """Judge a result for its part (or its tensor set), store it with its payload, then hand it on."""
        assert self.app.store is not None
        finished = self.app.wall_clock()
        armed = self._started.pop(m.id, (None, ""))[0]
        took = time.monotonic() - armed if armed is not None else (m.finished_at - m.requested_at) / self.app.clock_scale()
        started = finished - took
        part_id, recipe = self._part.pop(m.id, (self.app.parts.part_id, self.app.parts.recipe))
        rig = recipe.rig_for(self.app.config.rig) if recipe is not None else self.app.config.rig
        calibration = calibration_rule.calibration_state(rig, self.app.newest_checks(), finished)
        typed = self._station_flags(m, calibration)
        result = typed.to_dict()
        tensor_set = self.app.sets.of(recipe)
        study = self.app.studies.of(recipe) if tensor_set is None else None
        counted = study is not None and study.release(typed, m.id)
        if tensor_set is not None:
            outcome = PartOutcome(part_id, recipe.to_dict() if recipe else None, calibration=calibration,
                                  tensor_set=tensor_set.release(typed, m.id))
        elif study is not None:  # the reference part of a Type 1 study: not a part of the recipe (nor of its SPC)
            outcome = PartOutcome(part_id, recipe.to_dict() if recipe else None, calibration=calibration)
        else:
            outcome = dataclasses.replace(self.app.parts.release(typed, m.id, part_id, recipe, m.result, rig),
                                          calibration=calibration)
        timing, cfg, trace = m.to_dict().get("timing", {}), self.app.config, m.trace

        def build(uuid: str, seq: int) -> dict[str, Any]:
            return result_payload(result, uuid=uuid, seq=seq, device_id=cfg.device_id, trigger=m.requested_by,
                                  started_at=started, finished_at=finished, software_version=__version__,
                                  timing=timing, part=outcome.to_dict())

        try:
            stored = self._record(m.id, "ok", m.requested_by, started, finished, outcome, rig, result=result,
                                  build_payload=build, trace_t=trace.t if cfg.store_trace else None,
                                  trace_angle=trace.angle if cfg.store_trace else None, trace_meta=dict(trace.meta),
                                  enqueue={p.NAME: p.OUTBOX for p in self.app.publishers if p.OUTBOX})
        except BaseException:
            if tensor_set is not None:
                tensor_set.forget_last()
            elif study is not None:
                if counted:
                    study.forget_last()
            else:
                self.app.parts.undo_last()  # not stored: the release does not count for the part
            raise
        self._durable.append(m.id)
        if self.app.history is not None:  # the rig's repeat releases: the next release's reproducibility
            self.app.history.stored(stored)
        self.app.to_publishers("on_result", stored, m)
        self._note_stored(m.id)
        if (reply := self._reply.pop(m.id, None)) is not None:
            reply(CommandReply(V.TRIGGER, "done", data={"uuid": m.id, "seq": stored.seq}))
        log.info("measurement %s (seq %d) stored: J = %s kg·m², flags %s", m.id, stored.seq, typed.J,
                 ", ".join(typed.flags) or "none")
        self._part_done(outcome, recipe, m.id, typed.flags, finished)
        if tensor_set is not None:
            self.app.sets.released(tensor_set)
        if study is not None:
            self.app.studies.released(study)

    def _station_flags(self, m: Measurement, calibration: Mapping[str, Any] | None) -> IdentificationResult:
        """The result with the station's own flags raised (calibration due, capture slowed), before anything reads
        it."""
        raised = ((calibration is not None and calibration["due"], F.CALIBRATION_DUE),
                  (self.app.capture_watch.slowed(m.result.acquisition), F.CAPTURE_SLOWED))
        flags = m.result.flags + tuple(f for up, f in raised if up and f not in m.result.flags)
        return dataclasses.replace(m.result, flags=flags) if flags != m.result.flags else m.result

    def _part_done(self, outcome: PartOutcome, recipe: Recipe | None, measurement: str, flags: tuple[str, ...],
                   finished: float) -> None:
        """A part complete with this release: said, and a check standard's comparison kept with the history
        `moi check-standard` reads (a failed one makes the next results calibration_due)."""
        if outcome.verdict is None or recipe is None:
            return
        log.info("part %s (%s): %s", outcome.part_id or "(no ID)", recipe.name, outcome.verdict)
        self.app.to_publishers("on_part_done", recipe)
        check = outcome.part.check_standard if outcome.part is not None else None
        if check is None:
            return
        log.log(logging.INFO if check["passed"] else logging.WARNING, "check standard %s: E_n = %.2f (%s)",
                check["name"], check["E_n"], "pass" if check["passed"] else "FAIL")
        try:
            assert self.app.store is not None
            self.app.store.record_check_standard(dict(check) | {"part_id": outcome.part_id, "measurement": measurement,
                                                            "flags": list(flags)}, finished_at=finished)
            if self.app.history is not None:
                self.app.history.checked()
        except StoreError:
            log.exception("could not store the check standard of measurement %s", measurement)
        self.app.calibration_changed()  # a check standard may clear or raise the block

    def failed(self, event: Event) -> None:
        """A run that ended in FAULT or was aborted: stored with why."""
        assert event.measurement_id is not None
        armed, trigger = self._started.pop(event.measurement_id)
        finished = self.app.wall_clock()
        part_id, recipe = self._part.pop(event.measurement_id, (None, None))
        status = "failed" if event.state is State.FAULT else "aborted"
        if (reply := self._reply.pop(event.measurement_id, None)) is not None:
            reply(CommandReply(V.TRIGGER, "failed", "measurement_failed", event.reason or status,
                               {"uuid": event.measurement_id}))
        try:
            self._record(event.measurement_id, status, trigger, finished - (time.monotonic() - armed), finished,
                         _unjudged(part_id, recipe), error=event.reason)
            self._note_stored(event.measurement_id)
        except ServiceError:
            log.exception("could not store the %s measurement %s", status, event.measurement_id)

    def _note_stored(self, uuid: str) -> None:
        with self._cond:
            self.stored.append(uuid)
            self._cond.notify_all()

    def wait_stored(self, n: int, timeout: float) -> bool:
        """Wait until ``n`` measurements were stored since start (tests, demo). True if so."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while len(self.stored) < n:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True


def _unjudged(part_id: str | None, recipe: Recipe | None) -> PartOutcome:
    """The part keys of a run without a result: the part and the recipe it was measured for."""
    return PartOutcome(part_id, {"name": recipe.name, "version": recipe.version} if recipe is not None else None)
