"""The parts being measured: the releases of the open part counted, and its verdict made once it is complete.

A part is identified by its serial number (``part_id``, up to ``PART_ID_LENGTH`` ASCII characters), written by the
PLC or carried by the MQTT measure command. The same part ID and recipe continue the part until it has
``releases`` releases; a different part ID or recipe starts a new part (an unfinished part is reported as
abandoned in the log and in the next payload's ``release.abandoned``).
"""

from __future__ import annotations

import dataclasses
import logging
import uuid as uuidlib
from dataclasses import dataclass, field
from typing import Any

from measurement import Rig
from measurement.errors import MeasurementError
from measurement.result import IdentificationResult
from measurement.uncertainty import check_standard
from measurement.verdict import Reading, combine, judge_release
from service.parts.outcome import PartOutcome, PartSummary, ReleaseOutcome
from service.parts.recipes import Recipe, RecipeBook, check_part_id

log = logging.getLogger("moi.recipes")


@dataclass
class _OpenPart:
    uuid: str
    part_id: str | None
    recipe: Recipe
    readings: list[Reading] = field(default_factory=list)
    measurements: list[str] = field(default_factory=list)
    #: each release's identification (with its samples), for the part's joint identification
    identified: list[Any] = field(default_factory=list)


class PartTracker:
    """Counts the releases of the part being measured and makes its verdict (daemon's main loop thread only).

    The part ID and the active recipe are set by the PLC, MQTT or the config;
    ``release(result, measurement_id, part_id, recipe)`` is called once per
    successful measurement with what was current when it was triggered and
    returns what the payload adds (``PartOutcome``: part ID, recipe, release,
    part, verdict).
    """

    def __init__(self, book: RecipeBook, active: str | None = None) -> None:
        self.book = book
        self.recipe: Recipe | None = book.find(active) if active is not None else None
        self.part_id: str | None = None
        self._open: _OpenPart | None = None
        self._undo: tuple[_OpenPart | None, int] | None = None

    def select(self, key: str | int) -> Recipe:
        """Make a recipe active (RecipeError if it does not exist); 0 or "" deselects."""
        if key in (0, "", "0"):
            self.recipe = None
            return None  # type: ignore[return-value]
        self.recipe = self.book.find(key)
        return self.recipe

    def set_part_id(self, part_id: str | None) -> None:
        self.part_id = check_part_id(part_id) or None if part_id is not None else None

    @property
    def open_part(self) -> dict[str, Any] | None:
        o = self._open
        if o is None:
            return None
        return {"uuid": o.uuid, "part_id": o.part_id, "recipe": o.recipe.name, "done": len(o.readings),
                "of": o.recipe.releases}

    def release(self, result: IdentificationResult, measurement_id: str, part_id: str | None,
                recipe: Recipe | None, identified: Any = None, rig: Rig | None = None) -> PartOutcome:
        """Count one release; returns what its payload adds (the part's verdict once it is complete).

        identified, rig: the release's ``IdentificationResult`` and the rig it was identified on: with
        them for every release, the part's value is the releases' joint identification.
        """
        out = PartOutcome(part_id, recipe.to_dict() if recipe else None)
        o = self._open
        self._undo = (o, len(o.readings) if o is not None else 0)
        if recipe is None:
            self._abandon("no recipe is active")
            return out
        spec = recipe.spec
        if spec is None:  # a tensor recipe's release outside its set (the set ended while it ran): not judged
            self._abandon("a tensor recipe is active")
            return out
        abandoned = None
        if o is not None and (o.part_id != part_id or o.recipe.version != recipe.version):
            abandoned = self._abandon("a different part ID or recipe")
            o = None
        if o is None:
            o = self._open = _OpenPart(str(uuidlib.uuid4()), part_id, recipe)
        reading = Reading.from_result(result, spec.quantity)
        o.readings.append(reading)
        o.measurements.append(measurement_id)
        o.identified.append(identified)
        release = ReleaseOutcome(len(o.readings), recipe.releases, o.uuid, spec.quantity,
                                 judge_release(reading, spec, recipe.quality), abandoned)
        out = dataclasses.replace(out, release=release)
        if len(o.readings) >= recipe.releases:
            part = self._complete(o, part_id, recipe, rig)
            out = dataclasses.replace(out, part=part, verdict=part.verdict)
        return out

    def _complete(self, o: _OpenPart, part_id: str | None, recipe: Recipe, rig: Rig | None) -> PartSummary:
        """The verdict of the open part, complete with this release (and a check standard's comparison)."""
        spec = recipe.spec
        assert spec is not None
        joint_of = None
        if rig is not None and all(r is not None for r in o.identified):
            found, quantity = o.identified, spec.quantity

            def joint_of(used, quantity=quantity, found=found, rig=rig):
                from measurement.joint import joint_value  # scipy: only when a part completes
                try:
                    return joint_value([found[i] for i in used], rig, quantity)
                except MeasurementError as exc:
                    log.warning("part %s: the joint identification failed (%s); the weighted mean is used",
                                part_id or o.uuid, exc)
                    return None
        combined = combine(o.readings, spec, recipe.quality, joint_of)
        part = PartSummary.of(combined, o.uuid, part_id, tuple(o.measurements), spec.quantity)
        cs = recipe.check_standard
        if cs is not None and part.value is not None and part.U is not None:
            check = check_standard(cs["name"], spec.quantity, part.value, part.U, cs["reference"], cs["reference_U"])
            part = dataclasses.replace(part, check_standard=check.to_dict())
        for e in combined.excluded:
            log.warning("part %s: release %d excluded: %s", part_id or o.uuid, e["index"] + 1, e["reason"])
        self._open = None
        return part

    def undo_last(self) -> None:
        """Forget the last ``release`` (its measurement could not be stored)."""
        if self._undo is None:
            return
        o, n = self._undo
        if o is not None:
            del o.readings[n:]
            del o.measurements[n:]
            del o.identified[n:]
        self._open = o
        self._undo = None

    def _abandon(self, why: str) -> dict[str, Any] | None:
        o = self._open
        if o is None:
            return None
        log.warning("part %s (%s) abandoned after %d of %d releases: %s", o.part_id or "(no ID)", o.recipe.name,
                    len(o.readings), o.recipe.releases, why)
        self._open = None
        return {"part_uuid": o.uuid, "part_id": o.part_id, "recipe": o.recipe.name, "done": len(o.readings),
                "of": o.recipe.releases, "reason": why}
