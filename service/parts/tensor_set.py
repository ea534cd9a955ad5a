"""A guided tensor set: the orientations of a recipe's tensor plan measured one after the other.

The daemon's main loop owns one ``TensorSet`` while a tensor recipe is active.
The set says which orientation the operator mounts next (``progress``): the
CLI, the web page, the Modbus registers ``set_step`` / ``set_steps`` /
``set_orientation`` and the MQTT topic ``set`` all show that one dict. Each
stored release is counted for the current orientation; when it has the
recipe's ``releases``, the set moves on. The operator may redo an orientation
(its releases no longer count; they stay in the store), skip one (it is
excluded and named in the tensor's reasons), or abort the set (the releases
measured so far stay in the store, and the set is stored as aborted with the
links to them). When every orientation is measured or skipped the tensor is
computed (``measurement.tensor``) and the set is complete.
"""

from __future__ import annotations

import logging
import uuid as uuidlib
from dataclasses import dataclass, field
from typing import Any, Mapping

from measurement.errors import InvalidInput
from measurement.result import IdentificationResult
from measurement.rig import Rig
from measurement.tensor import TensorResult, solve
from measurement.tensor_inputs import AxisReading, RigShared, axis_reading
from service.errors import ServiceError

log = logging.getLogger("moi.tensor_set")

#: what an operator can do to a set
ACTIONS = ("redo", "skip", "abort")
RUNNING, COMPLETE, ABORTED, FAILED = "running", "complete", "aborted", "failed"


class SetError(ServiceError, InvalidInput):
    """An operator's action that does not apply to the set (says why)."""


@dataclass
class _Step:
    results: list[IdentificationResult] = field(default_factory=list)
    measurements: list[str] = field(default_factory=list)
    skipped: bool = False
    redone: int = 0


class TensorSet:
    """One guided set of a tensor recipe (main loop thread only).

    recipe: a recipe with ``tensor`` (its plan) and ``releases`` per orientation.
    rig: the rig its releases are identified with. part_id: the part's serial number, if any.
    """

    def __init__(self, recipe: Any, rig: Rig, part_id: str | None = None, started_at: float | None = None) -> None:
        if recipe.tensor is None:
            raise SetError(f"recipe {recipe.name!r} declares no [tensor] plan")
        self.recipe = recipe
        self.plan = recipe.tensor
        self.rig = rig
        self.shared = RigShared.of(rig)
        self.part_id = part_id
        self.uuid = str(uuidlib.uuid4())
        self.started_at = started_at
        self.steps = [_Step() for _ in self.plan.orientations]
        self.current = 0
        self.status = RUNNING
        self.result: TensorResult | None = None
        self.error: str | None = None
        self._undo: tuple[int, str, TensorResult | None, str | None] | None = None

    # -- what the operator sees -----------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.status != RUNNING

    def progress(self) -> dict[str, Any]:
        """The set's state for every front: step (1-based, 0 once done), steps, the orientation to mount."""
        n = len(self.plan.orientations)
        o = self.plan.orientations[self.current] if not self.done else None
        return {
            "uuid": self.uuid, "recipe": self.recipe.name, "part_id": self.part_id, "status": self.status,
            "step": self.current + 1 if o is not None else 0, "steps": n,
            "orientation": None if o is None else {**o.to_dict(), "index": self.current + 1,
                                                   "releases_done": len(self.steps[self.current].results),
                                                   "releases": self.recipe.releases},
            "measured": [o.name for o, s in zip(self.plan.orientations, self.steps)
                         if len(s.results) >= self.recipe.releases and not s.skipped],
            "skipped": [o.name for o, s in zip(self.plan.orientations, self.steps) if s.skipped],
            "error": self.error,
        }

    def instruction(self) -> str:
        """One line for the operator: what to mount next, or how the set ended."""
        if self.status == COMPLETE:
            return f"tensor set {self.recipe.name}: complete"
        if self.done:
            return f"tensor set {self.recipe.name}: {self.status}" + (f" ({self.error})" if self.error else "")
        o = self.plan.orientations[self.current]
        step = self.steps[self.current]
        where = "" if o.offset is None else f", centre of mass at [{', '.join(f'{v:g}' for v in o.offset)}] m from it"
        return (f"mount orientation {self.current + 1} of {len(self.steps)} '{o.name}': swing axis "
                f"[{', '.join(f'{v:.4g}' for v in o.axis)}] in the part's frame{where}; "
                f"release {len(step.results) + 1} of {self.recipe.releases}")

    # -- what happens -----------------------------------------------------------------------------
    def release(self, result: IdentificationResult, measurement_id: str) -> dict[str, Any]:
        """Count one stored release for the current orientation; returns the payload's ``set`` entry
        (the orientation it counted for, and the progress after it)."""
        if self.done:
            raise SetError(f"the set is {self.status}; start a new one")
        index = self.current
        step = self.steps[index]
        self._undo = (index, self.status, self.result, self.error)
        step.results.append(result)
        step.measurements.append(measurement_id)
        counted = {"orientation": self.plan.orientations[index].name, "index": index + 1,
                   "release": len(step.results), "of": self.recipe.releases}
        if len(step.results) >= self.recipe.releases:
            self._advance()
        return {**counted, "progress": self.progress()}

    def forget_last(self) -> None:
        """Undo the last ``release`` (its measurement could not be stored)."""
        if self._undo is None:
            return
        index, self.status, self.result, self.error = self._undo
        self.steps[index].results.pop()
        self.steps[index].measurements.pop()
        self.current = index
        self._undo = None

    def act(self, action: str, orientation: str | None = None) -> None:
        """The operator's ``redo`` (the named orientation, default the current one if it has releases,
        else the previous one), ``skip`` (the current one) or ``abort`` (the whole set)."""
        if action not in ACTIONS:
            raise SetError(f"unknown set action {action!r}; expected one of {', '.join(ACTIONS)}")
        if self.done:
            raise SetError(f"the set is {self.status}: nothing to {action}")
        self._undo = None
        if action == "abort":
            self.status = ABORTED
            self.error = "aborted by the operator"
            log.warning("tensor set %s aborted; its %d release(s) stay in the store", self.uuid,
                        sum(len(s.measurements) for s in self.steps))
            return
        if action == "skip":
            if orientation is not None and orientation != self.plan.orientations[self.current].name:
                raise SetError(f"only the current orientation ({self.plan.orientations[self.current].name!r}) "
                               "can be skipped")
            self.steps[self.current].skipped = True
            self._advance()
            return
        if orientation is not None:
            try:
                index = self.plan.index(orientation)
            except InvalidInput as exc:
                raise SetError(str(exc)) from None
        elif self.steps[self.current].results or self.current == 0:
            index = self.current
        else:
            index = self.current - 1
        step = self.steps[index]
        step.results.clear()
        step.measurements.clear()
        step.skipped = False
        step.redone += 1
        self.current = index

    def _advance(self) -> None:
        """To the next orientation still to measure; the tensor once there is none."""
        for i in list(range(self.current + 1, len(self.steps))) + list(range(0, self.current + 1)):
            s = self.steps[i]
            if not s.skipped and len(s.results) < self.recipe.releases:
                self.current = i
                return
        self._finish()

    def _finish(self) -> None:
        readings: list[AxisReading | None] = []
        for s in self.steps:
            if s.skipped:
                readings.append(AxisReading(None, None, releases=0, used=(), invalid="skipped by the operator"))
            else:
                readings.append(axis_reading(s.results, self.shared, self.recipe.quality))
        try:
            self.result = solve(self.plan, readings, self.shared)
            self.status = COMPLETE
        except InvalidInput as exc:  # too many orientations skipped or INVALID: the set cannot give a tensor
            self.status = FAILED
            self.error = str(exc)
            log.warning("tensor set %s: %s", self.uuid, exc)

    # -- what is stored -----------------------------------------------------------------------------
    def releases(self) -> dict[str, list[str]]:
        """Orientation name → the measurement UUIDs that count for it."""
        return {o.name: list(s.measurements) for o, s in zip(self.plan.orientations, self.steps)}

    def to_dict(self) -> dict[str, Any]:
        """The stored (and published) record of the set: plan, progress, releases, tensor (JSON-ready)."""
        return {"kind": "tensor_set", "uuid": self.uuid, "status": self.status, "recipe": self.recipe.name,
                "recipe_version": self.recipe.version, "part_id": self.part_id, "plan": self.plan.to_dict(),
                "releases": self.releases(), "skipped": self.progress()["skipped"], "error": self.error,
                "tensor": self.result.to_dict() if self.result is not None else None}


#: the file in the state directory that holds the running set's record, so that a set cut short by a kill is
#: recorded as interrupted at the next start
OPEN_SET_FILE = "tensor-set-open.json"


def interrupted(record: Mapping[str, Any], why: str) -> dict[str, Any]:
    """A running set's record as stored when the set was cut short (the daemon stopped or was killed): aborted,
    marked ``interrupted``, its releases stay stored."""
    measured = sum(len(v) for v in (record.get("releases") or {}).values())
    return dict(record) | {"status": ABORTED, "interrupted": True,
                           "error": f"interrupted: {why}; its {measured} release(s) stay stored"}
