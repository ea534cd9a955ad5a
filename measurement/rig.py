"""The rig: what swings and what restores it.

Two kinds:

* ``torsion``: restoring torque k·θ; J = k / ω_n².
* ``compound``: restoring torque m·g·S·sin θ (exact, not small-angle);
  J = m·g·S / ω_n².

A rig without its constant (no k, or no m and S) is valid: ω_n and the
damping normalised by J are still identified, J is then unknown (None).
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

from .effects import resolve_effects
from .errors import RigError

STANDARD_GRAVITY = 9.80665  # m/s²

RIG_KINDS = ("torsion", "compound")

_RIG_KEYS = {
    "kind", "stiffness", "stiffness_std", "tare_inertia", "tare_inertia_std",
    "mass", "com_distance", "g",
}
_OBJECT_KEYS = {"mass", "axis_offset"}
_MODEL_KEYS = {"declared"}
_SENSOR_KEYS = {"calibrated"}
_CALIBRATION_KEYS = {"date", "valid_days", "references", "source"}


def _positive(name: str, value: Any, unit: str, *, allow_zero: bool = False) -> float:
    """Return ``value`` as a finite float > 0 (or >= 0), else raise RigError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RigError(f"rig: {name} must be a number in {unit}, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        expect = ">= 0" if allow_zero else "> 0"
        raise RigError(f"rig: {name} must be {expect} {unit}, got {value!r}")
    return v


@dataclass(frozen=True)
class ObjectTransfer:
    """Parallel-axis transfer J_S = J_D − m_D·L²: the object's inertia about its own axis.

    mass: m_D, kg. axis_offset: L, m, from the pivot to the object's own axis.
    """

    mass: float
    axis_offset: float


@dataclass(frozen=True)
class CalibrationRecord:
    """When the rig was calibrated and for how long that holds (``[calibration]`` of the rig file).

    date: the calibration date. valid_days: validity period, days (None: no
    expiry). references: what was used (name, added inertia and its 1σ in
    kg·m², ω_n and its 1σ in rad/s...), as recorded by ``moi calibrate``.
    source: the calibration file it came from.
    """

    date: _dt.date
    valid_days: int | None = None
    references: tuple[dict[str, Any], ...] = ()
    source: str | None = None

    @property
    def valid_until(self) -> _dt.date | None:
        """The last day the calibration holds (None: no expiry)."""
        return None if self.valid_days is None else self.date + _dt.timedelta(days=self.valid_days)

    def due(self, today: _dt.date) -> bool:
        """True when ``today`` is past the validity period: results carry the flag ``calibration_due``."""
        until = self.valid_until
        return until is not None and today > until

    def state(self, today: _dt.date) -> dict[str, Any]:
        """As of ``today``: the date, the last valid day (None: no expiry), whether it is due, the days left."""
        until = self.valid_until
        return {"date": self.date.isoformat(), "valid_until": until.isoformat() if until else None,
                "due": self.due(today), "days_left": (until - today).days if until is not None else None}

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"date": self.date.isoformat()}
        if self.valid_days is not None:
            d["valid_days"] = self.valid_days
        if self.source is not None:
            d["source"] = self.source
        if self.references:
            d["references"] = [dict(r) for r in self.references]
        return d

    @classmethod
    def from_dict(cls, doc: Any) -> "CalibrationRecord":
        if not isinstance(doc, Mapping) or set(doc) - _CALIBRATION_KEYS or "date" not in doc:
            raise RigError("rig file: [calibration] needs date = YYYY-MM-DD, optional valid_days, references, source")
        date = doc["date"]
        if isinstance(date, _dt.datetime):
            date = date.date()
        elif isinstance(date, str):
            try:
                date = _dt.date.fromisoformat(date)
            except ValueError:
                raise RigError(f"rig file: [calibration] date must be a date like 2026-01-31, got {date!r}") from None
        if not isinstance(date, _dt.date):
            raise RigError(f"rig file: [calibration] date must be a date like 2026-01-31, got {date!r}")
        valid = doc.get("valid_days")
        if valid is not None and (isinstance(valid, bool) or not isinstance(valid, int) or valid <= 0):
            raise RigError(f"rig file: [calibration] valid_days must be a whole number of days > 0, got {valid!r}")
        refs = doc.get("references", [])
        if not isinstance(refs, list) or not all(isinstance(r, Mapping) for r in refs):
            raise RigError("rig file: [calibration] references must be a list of tables")
        source = doc.get("source")
        return cls(date, valid, tuple(dict(r) for r in refs), None if source is None else str(source))


@dataclass(frozen=True)
class Rig:
    """A pendulum rig. SI units throughout.

    kind: "torsion" | "compound".
    stiffness: k, N·m/rad (torsion); None when not calibrated.
    stiffness_std: 1σ of k from calibration, N·m/rad (optional).
    tare_inertia: J of the empty fixture, kg·m² (optional): J_object = J − tare.
    mass, com_distance: m (kg) and S (m) of the swinging body (compound).
    g: local gravity, m/s².
    declared: effect names the user declares (from ``[model] declared``).
    calibration: date, validity and references of the calibration (``[calibration]``), optional.
    sensor_calibrated: the angle sensor's scale and view are known (``[sensor] calibrated``):
        sensor effects that would fit the angle's scale from the swing (gain, view) are neither
        declared nor offered, so ω_n rests on the calibration, not on the fit.
    """

    kind: str
    stiffness: float | None = None
    stiffness_std: float | None = None
    tare_inertia: float | None = None
    tare_inertia_std: float | None = None
    mass: float | None = None
    com_distance: float | None = None
    g: float = STANDARD_GRAVITY
    object: ObjectTransfer | None = None
    declared: tuple[str, ...] = field(default=("viscous",))
    calibration: CalibrationRecord | None = None
    sensor_calibrated: bool = False

    def __post_init__(self) -> None:
        if self.kind not in RIG_KINDS:
            raise RigError(f"rig: unknown kind {self.kind!r}; expected one of {', '.join(RIG_KINDS)}")
        if self.kind == "torsion" and (self.mass is not None or self.com_distance is not None):
            # m and S do not enter a torsion rig's equation; accepting them silently
            # would let a user believe they were used.
            raise RigError("rig: mass/com_distance belong to a compound rig; kind is 'torsion'")
        if self.kind == "compound" and self.stiffness is not None:
            raise RigError("rig: stiffness belongs to a torsion rig; kind is 'compound'")
        # the rig carries the model declaration; the effect library checks it
        # (effects need only the rig's attributes, so the import runs one way)
        effects = resolve_effects(self.declared, self)
        if self.sensor_calibrated:
            scaling = [e.name for e in effects if e.scale_parameters]
            if scaling:
                raise RigError(f"rig: the sensor is calibrated ([sensor] calibrated = true) but [model] declares "
                               f"{', '.join(scaling)}, which fit the angle's scale; drop one or the other")

    # -- derived constants ---------------------------------------------------
    @property
    def restoring_constant(self) -> float | None:
        """C such that J = C / ω_n²: k (N·m/rad) or m·g·S (N·m); None if unknown."""
        if self.kind == "torsion":
            return self.stiffness
        if self.mass is not None and self.com_distance is not None:
            return self.mass * self.g * self.com_distance
        return None

    @property
    def restoring_constant_std(self) -> float | None:
        """1σ of the restoring constant from calibration, when known."""
        if self.kind == "torsion":
            return self.stiffness_std
        return None

    def with_declared(self, declared: tuple[str, ...] | list[str]) -> "Rig":
        return replace(self, declared=tuple(declared))

    # -- (de)serialisation ---------------------------------------------------
    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> "Rig":
        """Build a rig from the parsed rig TOML document ([rig], [object], [model], [calibration])."""
        unknown_tables = set(doc) - {"rig", "object", "model", "calibration", "sensor"}
        if unknown_tables:
            raise RigError(f"rig file: unknown table(s) {sorted(unknown_tables)}; expected [rig], [object], [model], "
                           "[calibration], [sensor]")
        rig = doc.get("rig")
        if not isinstance(rig, Mapping):
            raise RigError("rig file: missing [rig] table")
        unknown = set(rig) - _RIG_KEYS
        if unknown:
            raise RigError(f"rig file: unknown key(s) in [rig]: {sorted(unknown)}; expected {sorted(_RIG_KEYS)}")
        if "kind" not in rig:
            raise RigError("rig file: [rig] kind is missing; expected \"torsion\" or \"compound\"")
        kind = rig["kind"]
        if kind not in RIG_KINDS:
            raise RigError(f"rig file: unknown kind {kind!r}; expected one of {', '.join(RIG_KINDS)}")

        def opt(name: str, unit: str, allow_zero: bool = False) -> float | None:
            return None if name not in rig else _positive(name, rig[name], unit, allow_zero=allow_zero)

        obj = None
        if "object" in doc:
            o = doc["object"]
            if not isinstance(o, Mapping) or set(o) != _OBJECT_KEYS:
                raise RigError("rig file: [object] needs exactly mass (kg) and axis_offset (m)")
            obj = ObjectTransfer(
                mass=_positive("object.mass", o["mass"], "kg"),
                axis_offset=_positive("object.axis_offset", o["axis_offset"], "m", allow_zero=True),
            )
        declared: tuple[str, ...] = ("viscous",)
        if "model" in doc:
            m = doc["model"]
            if not isinstance(m, Mapping) or set(m) - _MODEL_KEYS:
                raise RigError("rig file: [model] takes only declared = [effect names]")
            d = m.get("declared", [])
            if not isinstance(d, list) or not all(isinstance(x, str) for x in d):
                raise RigError("rig file: [model] declared must be a list of effect names")
            declared = tuple(d)
        sensor_calibrated = False
        if "sensor" in doc:
            sensor = doc["sensor"]
            if not isinstance(sensor, Mapping) or set(sensor) - _SENSOR_KEYS:
                raise RigError("rig file: [sensor] takes only calibrated = true | false")
            sensor_calibrated = sensor.get("calibrated", False)
            if not isinstance(sensor_calibrated, bool):
                raise RigError(f"rig file: [sensor] calibrated must be true or false, got {sensor_calibrated!r}")
        return cls(
            kind=kind,
            stiffness=opt("stiffness", "N·m/rad"),
            stiffness_std=opt("stiffness_std", "N·m/rad", allow_zero=True),
            tare_inertia=opt("tare_inertia", "kg·m²", allow_zero=True),
            tare_inertia_std=opt("tare_inertia_std", "kg·m²", allow_zero=True),
            mass=opt("mass", "kg"),
            com_distance=opt("com_distance", "m"),
            g=opt("g", "m/s²") or STANDARD_GRAVITY,
            object=obj,
            declared=declared,
            calibration=CalibrationRecord.from_dict(doc["calibration"]) if "calibration" in doc else None,
            sensor_calibrated=sensor_calibrated,
        )

    def to_dict(self) -> dict[str, Any]:
        """The rig TOML document (None values left out)."""
        rig: dict[str, Any] = {"kind": self.kind}
        for key in ("stiffness", "stiffness_std", "tare_inertia", "tare_inertia_std", "mass", "com_distance"):
            value = getattr(self, key)
            if value is not None:
                rig[key] = value
        if self.g != STANDARD_GRAVITY:
            rig["g"] = self.g
        doc: dict[str, Any] = {"rig": rig}
        if self.object is not None:
            doc["object"] = {"mass": self.object.mass, "axis_offset": self.object.axis_offset}
        doc["model"] = {"declared": list(self.declared)}
        if self.calibration is not None:
            doc["calibration"] = self.calibration.to_dict()
        if self.sensor_calibrated:
            doc["sensor"] = {"calibrated": True}
        return doc
