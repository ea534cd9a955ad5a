"""The guided tensor set of the active tensor recipe, run for the daemon on its main loop thread: opened when
such a recipe and a part are selected, acted on by the operator, stored when it ends (complete, failed, aborted
or cut short), and kept in its file while it is open, so that a set a kill cut short is stored as interrupted at
the next start (``service.parts.tensor_set``: the set itself).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Callable

from measurement.errors import InvalidInput
from measurement.rig import Rig
from service.errors import ServiceError
from service.parts.recipes import Recipe
from service.parts.running_record import RunningRecord
from service.parts.tensor_set import COMPLETE, OPEN_SET_FILE, TensorSet, interrupted

log = logging.getLogger("moi.daemon")

#: what an operator's action on the set came to: (status "done" or "refused", the refusal's reason, its detail)
SetReply = tuple[str, str | None, str]


class SetDesk:
    """The daemon's tensor set. store(): the result store (None before start and after stop); announce(hook, arg):
    every publisher's hook (``on_set``, ``on_tensor_set``); refresh(): the live status again; wall_clock: Unix
    time, s."""

    def __init__(self, state_dir: Path, device_id: str, store: Callable[[], Any],
                 announce: Callable[[str, Any], None], refresh: Callable[[], None],
                 wall_clock: Callable[[], float]) -> None:
        self.file = RunningRecord(Path(state_dir) / OPEN_SET_FILE, "tensor set")
        self.device_id = device_id
        self._store, self._announce, self._refresh, self._now = store, announce, refresh, wall_clock
        self.current: TensorSet | None = None  # open, or just finished (shown until the next one starts)

    def open(self, recipe: Recipe | None, rig: Rig, part_id: str | None) -> None:
        """Open a set when ``recipe`` declares a tensor plan and none runs for it and this part (a finished set is
        shown until the next trigger or selection, which starts the next one); a running set of another recipe or
        part is aborted (its releases stay stored). rig: the set-up's (the recipe's own rig wins)."""
        current = self.current
        if current is not None and not current.done:
            if recipe is current.recipe and part_id == current.part_id:
                return
            current.act("abort")
            current.error = "a different recipe or part ID was selected"
            self.finish(current)
        if recipe is None or recipe.tensor is None:
            return
        s = self.current = TensorSet(recipe, recipe.rig_for(rig), part_id, self._now())
        log.info("tensor set %s started (%s, part %s): %s", s.uuid, recipe.name, part_id or "-", s.instruction())
        self.publish()

    def act(self, action: str, orientation: Any, source: str, busy: bool) -> SetReply:
        """An operator's action (``TensorSet.act``) from ``source``; busy: a measurement runs (only abort then)."""
        s = self.current
        if s is None or s.done:
            log.warning("set %s from %s: no tensor set is running", action, source)
            return "refused", "no_tensor_set", ""
        if busy and action != "abort":
            log.warning("set %s from %s refused: a measurement runs", action, source)
            return "refused", "busy", ""
        try:
            s.act(action, None if orientation is None else str(orientation))
        except InvalidInput as exc:
            log.warning("set %s from %s refused: %s", action, source, exc)
            return "refused", "malformed", str(exc)
        log.info("tensor set %s: %s by %s; %s", s.uuid, action, source, s.instruction())
        if s.done:  # act() may have ended the set (mypy keeps the narrowing of s.done above across the call)
            self.finish(s)  # type: ignore[unreachable]
        self.publish()
        return "done", None, ""

    def of(self, recipe: Recipe | None) -> TensorSet | None:
        """The running set a release of ``recipe`` counts for (None: a part's release, or the set ended, aborted,
        while it ran: the release counts for nothing)."""
        s = self.current if recipe is not None and recipe.tensor is not None else None
        return None if s is None or s.done or s.recipe is not recipe else s

    def released(self, s: TensorSet) -> None:
        """A release of ``s`` is stored: said, and the set stored once it is done."""
        log.info("tensor set %s: %s", s.uuid, s.instruction())
        if s.done:
            self.finish(s)
        self.publish()

    def finish(self, s: TensorSet, record: dict[str, Any] | None = None) -> None:
        """Store a finished set (complete, failed, aborted or interrupted) and hand it to the publishers."""
        store = self._store()
        assert store is not None
        record = record or s.to_dict()
        try:
            store.record_tensor_set(record, started_at=s.started_at, finished_at=self._now())
        except ServiceError:
            log.exception("could not store the tensor set %s", s.uuid)
            return
        self.file.drop()
        if s.status == COMPLETE and s.result is not None:
            r = s.result
            log.info("tensor set %s complete: principal moments %s kg·m², flags %s", s.uuid,
                     ", ".join(f"{v:.6g}" for v in r.principal_moments), ", ".join(r.flags) or "none")
        self._announce("on_tensor_set", record | {"device_id": self.device_id, "timestamp": self._now()})

    def interrupt(self, why: str) -> None:
        """A running set with releases, cut short: stored as interrupted (a new set begins at the next start)."""
        s = self.current
        if s is not None and not s.done and any(s.releases().values()) and self._store() is not None:
            log.warning("tensor set %s interrupted at %s: %s", s.uuid, s.instruction(), why)
            self.finish(s, interrupted(s.to_dict(), why))

    def recover(self) -> None:
        """The set a kill cut short (its file is left): stored as interrupted, and said; a new set starts."""
        left, store = self.file.left(), self._store()
        if left is None or store is None:
            return
        record = interrupted(left, "the daemon was stopped during the set without storing it")
        try:
            store.record_tensor_set(record, started_at=left.get("started_at"), finished_at=self._now())
        except ServiceError:
            log.exception("could not store the interrupted tensor set %s", left["uuid"])
            return
        self.file.drop()
        log.warning("tensor set %s (%s, part %s) was interrupted: %s; a new set starts at the first orientation",
                    left["uuid"], left.get("recipe"), left.get("part_id") or "-", record["error"])

    def publish(self) -> None:
        """The set's progress to every publisher (and to its file while it is open), then the live status."""
        if self.current is not None and not self.current.done:
            self.file.keep(self.current.to_dict() | {"started_at": self.current.started_at})
        progress = self.progress()
        if progress is not None:
            self._announce("on_set", progress)
        self._refresh()

    def progress(self) -> dict[str, Any] | None:
        """The set's progress with the operator's instruction (None: no set)."""
        s = self.current
        if s is None:
            return None
        return s.progress() | {"instruction": s.instruction(), "device_id": self.device_id}

    def registers(self) -> dict[str, int]:
        """The live status' set fields (none without a set)."""
        p = self.current.progress() if self.current is not None else None
        if p is None:
            return {}
        o = p["orientation"]
        return {"set_step": p["step"], "set_steps": p["steps"], "set_orientation": o["index"] if o else 0}
