"""The commands the appliance hears (button, Modbus, MQTT, Sparkplug, web, command line), acted on by the daemon's
main loop: a recipe and part ID applied, a trigger accepted or refused with its reason, an abort, a FAULT
acknowledged, an operator's action on the tensor set. A command that a stuck button or a looping client repeats is
said at most once per ``IGNORED_LOG_INTERVAL``.
"""

from __future__ import annotations

import logging
import time
from typing import Any, Callable, Mapping

from firmware_host import State
from measurement.errors import InvalidInput
from service.core import vocabulary as V
from service.parts.recipes import Recipe, RecipeError
from service.publish.replies import CommandReply, ReplyTo, fault_refusal

log = logging.getLogger("moi.daemon")

#: at most one "trigger ignored" line per this many seconds, s
IGNORED_LOG_INTERVAL = 10.0


class Dispatcher:
    """Acts on the commands of one appliance (``service.daemon.Appliance``: its sequencer, store, parts, tensor set
    desk, publishers and the calibration rule's block). ``accepted``: the source, the reply and the part ID and
    recipe of the last accepted trigger, paired with the run that starts next (ARMED)."""

    def __init__(self, app: Any) -> None:
        self.app = app
        self.accepted: tuple[str, ReplyTo | None, tuple[str | None, Recipe | None]] = ("unknown", None, (None, None))
        self._ignored_triggers = 0
        self._ignored_logged_at = -float("inf")
        self._refused_logged_at = -float("inf")

    def execute(self, name: str, source: str, data: Mapping[str, Any] | None,
                 reply: ReplyTo | None) -> CommandReply:
        """Act on one command; the outcome its source hears."""
        seq = self.app.sequencer
        assert seq is not None

        def refused(reason: str, detail: str = "") -> CommandReply:
            return CommandReply(name, "refused", reason, detail)

        command = V.COMMANDS.get(name)
        if command is None:
            log.warning("unknown command %r from %s", name, source)
            return refused("unknown_command", f"{name!r}")
        if command.sets_part and (data or command.act == "part"):
            if seq.busy:
                self._log_ignored(f"{name} from {source} refused: a measurement runs (the part cannot change "
                                  "during it)")
                return refused("busy")
            try:
                self._apply_part_data(data or {})
            except InvalidInput as exc:
                log.warning("%s from %s refused: %s", name, source, exc)
                return refused("unknown_recipe" if isinstance(exc, RecipeError) else "malformed", str(exc))
            if command.act == "part":
                return CommandReply(name, "done")
        return self._ACTS[command.act](self, name, command, source, data, reply)

    def _act_measure(self, name: str, command: V.Command, source: str, data: Mapping[str, Any] | None,
                     reply: ReplyTo | None) -> CommandReply:
        """A trigger (its part data applied already): a measurement starts, or the reason it cannot."""
        seq = self.app.sequencer
        assert seq is not None
        unwritable = self._store_unwritable()
        if unwritable is not None:
            self._log_refused(logging.ERROR, source, unwritable)
            return CommandReply(name, "refused", "store_unwritable", unwritable)
        block = self.app.measure_block() if seq.state is State.IDLE else None
        if block is not None:
            self._log_refused(logging.WARNING, source, block["detail"])
            self.app.show_block(True, again=True)
            return CommandReply(name, "refused", "calibration_due", block["detail"])
        if seq.request_measurement(source):
            self.accepted = (source, reply, (self.app.parts.part_id, self.app.parts.recipe))
            self.app.open_set()
            return CommandReply(name, "accepted")
        self._log_ignored(f"trigger from {source} ignored (state {seq.state.value})")
        state = seq.state
        if state is State.FAULT:
            return CommandReply(name, "refused", "fault",
                                fault_refusal(seq.last_fault, self.app.contact()))
        return CommandReply(name, "refused", "busy" if seq.busy else "not_ready", f"state {state.value}")

    def _act_stop(self, name: str, command: V.Command, source: str, data: Mapping[str, Any] | None,
                  reply: ReplyTo | None) -> CommandReply:
        """Abort the running measurement, or acknowledge a FAULT (an abort does both)."""
        seq = self.app.sequencer
        assert seq is not None
        if seq.state is State.FAULT:
            seq.abort(f"fault acknowledged by {source}")
            return CommandReply(name, "done")
        if name == V.ABORT and seq.abort(f"aborted by {source}"):
            return CommandReply(name, "done")
        log.info("%s from %s: nothing to %s", name, source, "abort" if name == V.ABORT else "acknowledge")
        return CommandReply(name, "refused", "nothing_to_abort")

    def _act_set(self, name: str, command: V.Command, source: str, data: Mapping[str, Any] | None,
                 reply: ReplyTo | None) -> CommandReply:
        """An operator action of the tensor set: the coil's own (``set_action``) or the data's ``action``."""
        action = command.set_action or str((data or {}).get("action"))
        assert self.app.sequencer is not None
        status, reason, detail = self.app.sets.act(action, (data or {}).get("orientation"), source,
                                                   self.app.sequencer.busy)
        return CommandReply(name, status, reason, detail)

    def _act_study(self, name: str, command: V.Command, source: str, data: Mapping[str, Any] | None,
                   reply: ReplyTo | None) -> CommandReply:
        """Start or abort the guided Type 1 study, or the reason it cannot (``StudyDesk.act``)."""
        app = self.app
        assert app.sequencer is not None
        running = app.sets.current
        other = (f"a tensor set of {running.recipe.name} runs: finish or abort it first"
                 if running is not None and not running.done else None)
        block = app.measure_block()
        status, reason, detail = app.studies.act(data or {}, source, recipe=app.parts.recipe,
                                                 part_id=app.parts.part_id, busy=app.sequencer.busy, other=other,
                                                 block=block["detail"] if block is not None else None,
                                                 who=V.source_words(source))
        if status == "refused":
            log.warning("%s from %s refused: %s", name, source, detail)
        return CommandReply(name, status, reason, detail)

    #: how it acts on each ``Command.act`` but "part" (whose data is applied in ``_execute``)
    _ACTS: dict[str, Callable[..., CommandReply]] = {"measure": _act_measure, "stop": _act_stop, "set": _act_set,
                                                     "study": _act_study}

    def _log_ignored(self, what: str) -> None:
        """One line per IGNORED_LOG_INTERVAL for the commands a stuck button or a looping client repeats."""
        self._ignored_triggers += 1
        now = time.monotonic()
        if now - self._ignored_logged_at >= IGNORED_LOG_INTERVAL:
            log.info("%s; %d command(s) ignored or refused since the last such line", what, self._ignored_triggers)
            self._ignored_logged_at, self._ignored_triggers = now, 0

    def _log_refused(self, level: int, source: str, why: str) -> None:
        """A refused trigger in the log, at most one line per IGNORED_LOG_INTERVAL (a stuck button repeats it)."""
        now = time.monotonic()
        if now - self._refused_logged_at >= IGNORED_LOG_INTERVAL:
            log.log(level, "trigger from %s refused: %s", source, why)
            self._refused_logged_at = now

    def _store_unwritable(self) -> str | None:
        """Why no measurement may start (its result could not be kept), or None. After a failed write
        a write is tried again here, so measuring resumes as soon as space is freed."""
        store = self.app.store
        if store is None or store.write_failure is None or store.writable():
            return None
        return (f"the result store cannot be written ({store.write_failure}); free space in "
                f"{str(self.app.config.state_dir)!r}: the results kept so far are safe and still delivered")

    def _apply_part_data(self, data: Mapping[str, Any]) -> None:
        """Select a recipe and/or set the part ID (InvalidInput when unknown or malformed)."""
        if data.get("recipe") is not None:
            r = self.app.parts.select(data["recipe"])
            log.info("recipe %s", f"{r.number} {r.name!r} (version {r.version}) active" if r else "deselected")
            self.app.to_publishers("on_recipe", r)
        if "part_id" in data:
            self.app.parts.set_part_id(data["part_id"])
            self.app.to_publishers("on_part_id", self.app.parts.part_id)
        self.app.open_set()
