"""A release's part outcome, typed: the release's decision, the part's once the release completes it, the part
verdict, and what the payload carries beside them (part ID, recipe, calibration, tensor-set progress).

``PartTracker.release`` makes it; a reader of a stored or received payload reads it once, where the row is
loaded (``PartOutcome.from_dict``), and its fields from there. The dict form (``to_dict``) exists only on the
wire and in the store: its keys are the payload's part keys (``service.publish.payload.PART_KEYS``), and a part's
value is written both as ``mean`` and as ``value`` there, as the payload has always carried it; here it has one
name, ``value``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from measurement.verdict import Decision, PartResult


def _decision(d: Mapping[str, Any], value: Any) -> Decision:
    """The decision a release's or a part's dict form holds (a key an older row lacks: None)."""
    return Decision(verdict=d.get("verdict") or "", value=value, u_c=d.get("u_c"), U=d.get("U"),
                    deviation=d.get("deviation"), zone=d.get("zone"), rule=d.get("rule") or "",
                    reasons=tuple(d.get("reasons") or ()))


class _Decided:
    """What a release and a part both read from their decision: the verdict ('' read as None) and the value."""

    decision: Decision

    @property
    def verdict(self) -> str | None:
        return self.decision.verdict or None

    @property
    def value(self) -> float | None:
        return self.decision.value


@dataclass(frozen=True)
class ReleaseOutcome(_Decided):
    """One release of a part: its index of ``of``, the part it counts for, its own decision (kg·m²), and the
    unfinished earlier part it abandoned by starting a new one (None: none)."""

    index: int
    of: int
    part_uuid: str | None
    quantity: str
    decision: Decision
    abandoned: Mapping[str, Any] | None = None

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "ReleaseOutcome":
        return cls(int(d.get("index") or 0), int(d.get("of") or 0), d.get("part_uuid"), d.get("quantity") or "J",
                   _decision(d, d.get("value")), d.get("abandoned"))

    def to_dict(self) -> dict[str, Any]:
        return {"index": self.index, "of": self.of, "part_uuid": self.part_uuid, "quantity": self.quantity,
                **self.decision.to_dict(), "abandoned": None if self.abandoned is None else dict(self.abandoned)}


@dataclass(frozen=True)
class PartSummary(_Decided):
    """A complete part (kg·m²): its releases' values, which were used and which excluded (index, reason), the
    statistics of the used ones, the decision (its ``value`` is the part's value: the joint identification's or
    the weighted mean), and a check standard's comparison with its certificate (None: a part type)."""

    uuid: str
    part_id: str | None
    measurements: tuple[str, ...]
    quantity: str
    releases: int
    values: tuple[float | None, ...]
    used: tuple[int, ...]
    excluded: tuple[Mapping[str, Any], ...]
    std: float | None
    u_typeA: float | None
    u_fit: float | None
    u_systematic: float | None
    z: tuple[float | None, ...]
    decision: Decision
    joint: Mapping[str, Any] | None = None
    uncertainty: Mapping[str, Any] | None = None
    check_standard: Mapping[str, Any] | None = None

    @property
    def U(self) -> float | None:
        return self.decision.U

    @classmethod
    def of(cls, result: PartResult, uuid: str, part_id: str | None, measurements: tuple[str, ...],
           quantity: str) -> "PartSummary":
        """The summary of the part ``combine`` judged."""
        return cls(uuid, part_id, measurements, quantity, result.releases, result.values, result.used,
                   result.excluded, result.std, result.u_typeA, result.u_fit, result.u_systematic, result.z,
                   result.decision, result.joint, result.uncertainty)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "PartSummary":
        value = d.get("value", d.get("mean"))
        return cls(d.get("uuid") or "", d.get("part_id"), tuple(d.get("measurements") or ()),
                   d.get("quantity") or "J", int(d.get("releases") or 0), tuple(d.get("values") or ()),
                   tuple(d.get("used") or ()), tuple(d.get("excluded") or ()), d.get("std"), d.get("u_typeA"),
                   d.get("u_fit"), d.get("u_systematic"), tuple(d.get("z") or ()), _decision(d, value),
                   d.get("joint"), d.get("uncertainty"), d.get("check_standard"))

    def to_dict(self) -> dict[str, Any]:
        out = {"uuid": self.uuid, "part_id": self.part_id, "measurements": list(self.measurements),
               "quantity": self.quantity, "releases": self.releases, "values": list(self.values),
               "used": list(self.used), "excluded": [dict(e) for e in self.excluded], "mean": self.value,
               "std": self.std, "u_typeA": self.u_typeA, "u_fit": self.u_fit, "u_systematic": self.u_systematic,
               "z": list(self.z), "joint": self.joint, "uncertainty": self.uncertainty, **self.decision.to_dict()}
        if self.check_standard is not None:
            out["check_standard"] = dict(self.check_standard)
        return out


@dataclass(frozen=True)
class PartOutcome:
    """What a release adds to its payload: the part ID and recipe (the recipe's dict form, as judged with; None
    without one), the release's outcome, the part's once complete, the part verdict, the rig's calibration state
    and, for a tensor recipe, the orientation it counted for (each None when it does not apply)."""

    part_id: str | None = None
    recipe: Mapping[str, Any] | None = None
    release: ReleaseOutcome | None = None
    part: PartSummary | None = None
    verdict: str | None = None
    calibration: Mapping[str, Any] | None = None
    tensor_set: Mapping[str, Any] | None = None

    @property
    def decision(self) -> Decision | None:
        """The decision the verdict comes from: the part's once the release completes it, else the release's."""
        made = self.part or self.release
        return made.decision if made is not None else None

    @property
    def shown_verdict(self) -> str | None:
        """The verdict a reader shows: the part's once complete, else the release's (None without a recipe)."""
        d = self.decision
        return self.verdict or (d.verdict if d is not None else None) or None

    @property
    def not_decidable(self) -> bool:
        """INVALID, or in the guard band's uncertainty range: the verdict cannot decide."""
        d = self.decision
        return self.shown_verdict == "INVALID" or (d is not None and d.zone == "uncertainty")

    @classmethod
    def from_dict(cls, payload: Mapping[str, Any] | None) -> "PartOutcome":
        """From a payload (or its part keys); keys it lacks are None."""
        p = payload or {}
        release, part = p.get("release"), p.get("part")
        return cls(p.get("part_id"), p.get("recipe") or None,
                   ReleaseOutcome.from_dict(release) if release else None,
                   PartSummary.from_dict(part) if part else None, p.get("verdict"), p.get("calibration") or None,
                   p.get("tensor_set") or None)

    def to_dict(self) -> dict[str, Any]:
        """The payload's part keys."""
        return {"part_id": self.part_id, "recipe": None if self.recipe is None else dict(self.recipe),
                "release": self.release.to_dict() if self.release is not None else None,
                "part": self.part.to_dict() if self.part is not None else None, "verdict": self.verdict,
                "calibration": None if self.calibration is None else dict(self.calibration),
                "tensor_set": None if self.tensor_set is None else dict(self.tensor_set)}

    def store_columns(self) -> dict[str, Any]:
        """The store's part columns."""
        recipe, rel, part = self.recipe or {}, self.release, self.part
        return {"part_id": self.part_id, "part_uuid": rel.part_uuid if rel is not None else None,
                "recipe": recipe.get("name"), "recipe_version": recipe.get("version"),
                "release_index": rel.index if rel is not None else None,
                "releases": rel.of if rel is not None else None,
                "verdict": rel.verdict if rel is not None else None, "part_verdict": self.verdict,
                "part_value": part.value if part is not None else None,
                "part_U": part.U if part is not None else None}
