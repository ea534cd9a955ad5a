"""The rig: what swings and what restores it.

Four kinds:

* ``torsion``: restoring torque k·θ; J = k / ω_n².
* ``compound``: restoring torque m·g·S·sin θ (exact, not small-angle);
  J = m·g·S / ω_n².
* ``bifilar`` / ``trifilar``: the part hung on two wires D apart (each R = D/2 from the axis) or three
  on a circle of radius R, of length L; the wires' exact law of the twist (``measurement.restoring``);
  J = m·g·R² / (L·ω_n²) (m·g·D²/(4L·ω_n²) for a bifilar).

A rig without its constant (no k, or no m and S) is valid: ω_n and the
damping normalised by J are still identified, J is then unknown (None).
"""

from __future__ import annotations

import datetime as _dt
import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

from .effects import resolve_effects
from .errors import RigError
from .reproducibility import Reproducibility, calibrated
from .restoring import RIG_KINDS, WIRE_SUSPENSIONS, wire_geometry
from .trace import READINGS
from .uncertainty import check_covariance

STANDARD_GRAVITY = 9.80665  # m/s²

_RIG_KEYS = {
    "kind", "stiffness", "stiffness_std", "tare_inertia", "tare_inertia_std",
    "mass", "com_distance", "g", "stiffness_tare_covariance", "mass_std", "com_distance_std", "g_std",
    "length", "length_std", "wire_length", "wire_length_std", "spacing", "spacing_std", "radius", "radius_std",
}
#: the keys only one kind takes, and what they are
_KIND_KEYS = {
    "torsion": {"stiffness": "k"},
    "compound": {"com_distance": "S", "length": "the equivalent pendulum length"},
    "bifilar": {"spacing": "the wires' spacing D"},
    "trifilar": {"radius": "the wires' circle radius R"},
}
_WIRE_RIG_KEYS = ("wire_length", "wire_length_std", "spacing", "spacing_std", "radius", "radius_std")
_OBJECT_KEYS = {"mass", "axis_offset"}
_OBJECT_STD_KEYS = {"mass_std", "axis_offset_std"}
_MODEL_KEYS = {"declared"}
_SENSOR_KEYS = {"calibrated", "clock_accuracy_ppm", "angle_scale_std"}
_CALIBRATION_KEYS = {"date", "valid_days", "references", "source", "amplitude"}
#: the rig's reproducibility between releases its calibration pooled (``moi calibrate``; optional)
_REPRO_KEYS = {"reproducibility", "reproducibility_dof"}


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
    mass_std, axis_offset_std: their 1σ (kg, m); None: not stated.
    """

    mass: float
    axis_offset: float
    mass_std: float | None = None
    axis_offset_std: float | None = None


@dataclass(frozen=True)
class CalibrationRecord:
    """When the rig was calibrated and for how long that holds (``[calibration]`` of the rig file).

    date: the calibration date. valid_days: validity period, days (None: no
    expiry). references: what was used (name, added inertia and its 1σ in
    kg·m², ω_n and its 1σ in rad/s...), as recorded by ``moi calibrate``.
    source: the calibration file it came from.
    amplitude: the swing amplitude (rad) the references' ω_n were read at (None: not stated). A spring
    whose stiffness changes with the amplitude is calibrated at this one: a part's ω is read there too
    (``identification.measurand``).
    reproducibility, reproducibility_dof: the relative 1σ of ω_n between releases that the references released
    more than once showed (ISO 5725-2 pooled, ``measurement.reproducibility``) and its degrees of freedom
    Σ(n_i − 1); None: not measured (one release of each reference).
    """

    date: _dt.date
    valid_days: int | None = None
    references: tuple[dict[str, Any], ...] = ()
    source: str | None = None
    amplitude: float | None = None
    reproducibility: float | None = None
    reproducibility_dof: int | None = None

    def reproducibility_figure(self) -> Reproducibility | None:
        """The kept figure (source "rig") with what it pooled (the references named more than once); None: none."""
        if self.reproducibility is None or self.reproducibility_dof is None:
            return None
        names = Counter(str(r.get("name")) for r in self.references)
        repeated = [n for n in names.values() if n > 1]
        return calibrated(self.reproducibility, float(self.reproducibility_dof), len(repeated), sum(repeated))

    @property
    def valid_until(self) -> _dt.date | None:
        """The last day the calibration holds (None: no expiry)."""
        return None if self.valid_days is None else self.date + _dt.timedelta(days=self.valid_days)

    def due(self, today: _dt.date) -> bool:
        """True when ``today`` is past the validity period: results carry the flag ``calibration_due``."""
        until = self.valid_until
        return until is not None and today > until

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"date": self.date.isoformat()}
        if self.valid_days is not None:
            d["valid_days"] = self.valid_days
        if self.source is not None:
            d["source"] = self.source
        if self.amplitude is not None:
            d["amplitude"] = self.amplitude
        if self.references:
            d["references"] = [dict(r) for r in self.references]
        if self.reproducibility is not None:
            d |= {"reproducibility": self.reproducibility, "reproducibility_dof": self.reproducibility_dof}
        return d

    @classmethod
    def from_dict(cls, doc: Any) -> "CalibrationRecord":
        if not isinstance(doc, Mapping) or set(doc) - _CALIBRATION_KEYS - _REPRO_KEYS or "date" not in doc:
            raise RigError("rig file: [calibration] needs date = YYYY-MM-DD, optional valid_days, references, source, "
                           "amplitude, reproducibility and reproducibility_dof")
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
        amplitude = doc.get("amplitude")
        if amplitude is not None:
            amplitude = _positive("[calibration] amplitude", amplitude, "rad", allow_zero=True)
        return cls(date, valid, tuple(dict(r) for r in refs), None if source is None else str(source), amplitude,
                   *_reproducibility(doc))


@dataclass(frozen=True)
class Rig:
    """A pendulum rig. SI units throughout.

    kind: "torsion" | "compound" | "bifilar" | "trifilar".
    stiffness: k, N·m/rad (torsion); None when not calibrated.
    stiffness_std: 1σ of k from calibration, N·m/rad (optional).
    tare_inertia: J of the empty fixture, kg·m² (optional): J_object = J − tare.
    tare_inertia_std: its 1σ, kg·m²; stiffness_tare_covariance: cov(k, I0), N·m/rad·kg·m²
        (``moi calibrate`` writes all three: k and I0 come out of one regression).
    mass, com_distance: m (kg) and S (m) of the swinging body (compound); mass_std, com_distance_std their 1σ.
    g: local gravity, m/s²; g_std its 1σ (None: not stated; standard gravity may be 0.3 % off the local g).
    length, length_std: the equivalent pendulum length L = J/(m·S) and its 1σ, m (compound; a small bob on a
        string: the pivot to the bob's centre): the result gives g = ω_n²·L (None: not stated).
    wire_length, wire_length_std: L of a wire suspension's wires (bifilar, trifilar), m; spacing, spacing_std: D
        between a bifilar's two wires, m; radius, radius_std: R of a trifilar's wires' circle (at the part and at
        the top), m. mass (kg) is then the whole hanging mass, the part's and its platform's.
    clock_accuracy_ppm: 1σ of the sample clock's frequency, ppm (``[sensor]``; None: not stated).
    angle_scale_std: 1σ of a calibrated angle sensor's scale, relative (``[sensor]``; None: not stated).
    declared: effect names the user declares (from ``[model] declared``).
    calibration: date, validity and references of the calibration (``[calibration]``), optional.
    sensor_calibrated: the angle sensor's scale and view are known (``[sensor] calibrated``):
        sensor effects that would fit the angle's scale from the swing (gain, view) are neither
        declared nor offered, so ω_n rests on the calibration, not on the fit.
    measures: what the sensor reads, "angle" (rad: an encoder, a camera) or "rate" (rad/s: a gyro or an
        IMU's rate axis); set from the trace it identifies (a trace's ``quantity``), not from the rig file.
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
    stiffness_tare_covariance: float | None = None
    mass_std: float | None = None
    com_distance_std: float | None = None
    g_std: float | None = None
    clock_accuracy_ppm: float | None = None
    angle_scale_std: float | None = None
    measures: str = "angle"
    length: float | None = None
    length_std: float | None = None
    wire_length: float | None = None
    wire_length_std: float | None = None
    spacing: float | None = None
    spacing_std: float | None = None
    radius: float | None = None
    radius_std: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in RIG_KINDS:
            raise RigError(f"rig: unknown kind {self.kind!r}; expected one of {', '.join(RIG_KINDS)}")
        if self.measures not in READINGS:
            raise RigError(f"rig: the sensor measures {self.measures!r}; expected one of {', '.join(READINGS)}")
        self._check_kind_keys()
        if self.angle_scale_std is not None and not self.sensor_calibrated:
            # an uncalibrated sensor's scale is fitted from the swing (gain, view) or does not enter ω_n:
            # a σ for it would be counted for nothing
            raise RigError("rig: [sensor] angle_scale_std is the σ of a calibrated sensor's scale; "
                           "add calibrated = true or drop it")
        if self.stiffness_tare_covariance is not None:
            check_covariance("rig: stiffness_tare_covariance", self.stiffness_tare_covariance,
                             self.stiffness_std, self.tare_inertia_std)
        # the rig carries the model declaration; the effect library checks it
        # (effects need only the rig's attributes, so the import runs one way)
        effects = resolve_effects(self.declared, self)
        if self.sensor_calibrated:
            scaling = [e.name for e in effects if e.scale_parameters]
            if scaling:
                raise RigError(f"rig: the sensor is calibrated ([sensor] calibrated = true) but [model] declares "
                               f"{', '.join(scaling)}, which fit the angle's scale; drop one or the other")

    def _check_kind_keys(self) -> None:
        """A key of another kind is refused: it would not enter this rig's equation, and accepting it
        silently would let a user believe it was used."""
        for kind, keys in _KIND_KEYS.items():
            for key, what in keys.items():
                if kind != self.kind and getattr(self, key) is not None:
                    raise RigError(f"rig: {key} ({what}) belongs to a {kind} rig; kind is {self.kind!r}")
        if self.kind == "torsion" and self.mass is not None:
            raise RigError("rig: mass belongs to a compound or wire-suspension rig; kind is 'torsion'")
        if self.kind not in WIRE_SUSPENSIONS:
            if self.wire_length is not None:
                raise RigError(f"rig: wire_length belongs to a bifilar or trifilar rig; kind is {self.kind!r}")
            return
        size = "spacing" if self.kind == "bifilar" else "radius"
        if self.wire_length is None or getattr(self, size) is None:
            raise RigError(f"rig: a {self.kind} rig needs wire_length (m) and {size} (m): its law is its geometry")
        assert self.wire_radius is not None and self.wire_length is not None
        if self.wire_radius >= self.wire_length:
            # beyond it the part could not hang below the wires' upper ends at every twist
            raise RigError(f"rig: a {self.kind} rig's wires must be longer than their distance from the axis "
                           f"(wire_length {self.wire_length:g} m, distance {self.wire_radius:g} m)")

    # -- derived constants ---------------------------------------------------
    @property
    def reproducibility(self) -> Reproducibility | None:
        """The scatter of ω_n between releases its calibration measured (source "rig"); None: not measured."""
        return None if self.calibration is None else self.calibration.reproducibility_figure()

    @property
    def wire_radius(self) -> float | None:
        """R, the wires' distance from the axis (m): D/2 on a bifilar, the circle's radius on a trifilar."""
        if self.kind == "bifilar" and self.spacing is not None:
            return self.spacing / 2.0
        return self.radius if self.kind == "trifilar" else None

    @property
    def wire_radius_std(self) -> float | None:
        if self.kind == "bifilar" and self.spacing_std is not None:
            return self.spacing_std / 2.0
        return self.radius_std if self.kind == "trifilar" else None

    @property
    def geometry(self) -> tuple[float, ...]:
        """A wire suspension's (e, b) for its law (``restoring.wire_geometry``); empty for the other kinds."""
        if self.kind not in WIRE_SUSPENSIONS or self.wire_radius is None or self.wire_length is None:
            return ()
        return wire_geometry(self.wire_radius, self.wire_length, self.g)

    @property
    def restoring_constant(self) -> float | None:
        """C such that J = C / ω_n²: k (N·m/rad), m·g·S (N·m) or m·g·R²/L (N·m); None if unknown."""
        if self.kind == "torsion":
            return self.stiffness
        if self.mass is None:
            return None
        if self.kind in WIRE_SUSPENSIONS:
            assert self.wire_radius is not None and self.wire_length is not None
            return self.mass * self.g * self.wire_radius**2 / self.wire_length
        return None if self.com_distance is None else self.mass * self.g * self.com_distance

    @property
    def restoring_constant_std(self) -> float | None:
        """1σ of the restoring constant from calibration (k) or from m, g and the lengths, when any is stated."""
        if self.kind == "torsion":
            return self.stiffness_std
        c = self.restoring_constant
        if self.kind in WIRE_SUSPENSIONS:
            lengths = [(2.0, self.wire_radius_std, self.wire_radius), (1.0, self.wire_length_std, self.wire_length)]
        else:
            lengths = [(1.0, self.com_distance_std, self.com_distance)]
        parts = [(1.0, self.mass_std, self.mass), (1.0, self.g_std, self.g)] + lengths
        if c is None or all(std is None for _, std, _ in parts):
            return None
        return c * math.sqrt(sum((power * (std or 0.0) / (value or 1.0)) ** 2 for power, std, value in parts))

    def with_declared(self, declared: tuple[str, ...] | list[str]) -> "Rig":
        return replace(self, declared=tuple(declared))

    # -- (de)serialisation ---------------------------------------------------
    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> "Rig":
        """Build a rig from the parsed rig TOML document ([rig], [object], [model], [calibration], [sensor])."""
        rig = _rig_table(doc)
        obj = _object_transfer(doc["object"]) if "object" in doc else None
        declared = _declared(doc["model"]) if "model" in doc else ("viscous",)
        sensor_calibrated, sensor = _sensor(doc["sensor"]) if "sensor" in doc else (False, {})
        covariance = rig.get("stiffness_tare_covariance")
        if covariance is not None and (isinstance(covariance, bool) or not isinstance(covariance, (int, float))):
            raise RigError(f"rig: stiffness_tare_covariance must be a number in N·m/rad·kg·m², got {covariance!r}")
        numbers: dict[str, Any] = {name: None if name not in rig else _positive(name, rig[name], unit, allow_zero=std)
                   for name, unit, std in _RIG_NUMBERS}
        stds: dict[str, Any] = {name: None if name not in sensor else _positive(f"sensor.{name}", sensor[name], unit, allow_zero=True)
                for name, unit in (("clock_accuracy_ppm", "ppm"), ("angle_scale_std", "1 (relative)"))}
        return cls(
            kind=rig["kind"], **(numbers | {"g": numbers["g"] or STANDARD_GRAVITY}), **stds, object=obj,
            declared=declared, sensor_calibrated=sensor_calibrated,
            calibration=CalibrationRecord.from_dict(doc["calibration"]) if "calibration" in doc else None,
            stiffness_tare_covariance=None if covariance is None else float(covariance),
        )

    def to_dict(self) -> dict[str, Any]:
        """The rig TOML document (None values left out)."""
        rig: dict[str, Any] = {"kind": self.kind}
        for key in ("stiffness", "stiffness_std", "tare_inertia", "tare_inertia_std", "stiffness_tare_covariance",
                    "mass", "mass_std", "com_distance", "com_distance_std", "length", "length_std") + _WIRE_RIG_KEYS:
            value = getattr(self, key)
            if value is not None:
                rig[key] = value
        if self.g != STANDARD_GRAVITY:
            rig["g"] = self.g
        if self.g_std is not None:
            rig["g_std"] = self.g_std
        doc: dict[str, Any] = {"rig": rig}
        if self.object is not None:
            doc["object"] = {"mass": self.object.mass, "axis_offset": self.object.axis_offset}
            for key in ("mass_std", "axis_offset_std"):
                if getattr(self.object, key) is not None:
                    doc["object"][key] = getattr(self.object, key)
        doc["model"] = {"declared": list(self.declared)}
        if self.calibration is not None:
            doc["calibration"] = self.calibration.to_dict()
        sensor: dict[str, Any] = {"calibrated": True} if self.sensor_calibrated else {}
        for key in ("clock_accuracy_ppm", "angle_scale_std"):
            if getattr(self, key) is not None:
                sensor[key] = getattr(self, key)
        if sensor:
            doc["sensor"] = sensor
        return doc


#: the numbers of [rig]: (key, unit, whether 0 is allowed: the standard uncertainties and the tare)
_RIG_NUMBERS = (
    ("stiffness", "N·m/rad", False), ("stiffness_std", "N·m/rad", True), ("tare_inertia", "kg·m²", True),
    ("tare_inertia_std", "kg·m²", True), ("mass", "kg", False), ("com_distance", "m", False), ("g", "m/s²", False),
    ("mass_std", "kg", True), ("com_distance_std", "m", True), ("g_std", "m/s²", True),
    ("length", "m", False), ("length_std", "m", True), ("wire_length", "m", False), ("wire_length_std", "m", True),
    ("spacing", "m", False), ("spacing_std", "m", True), ("radius", "m", False), ("radius_std", "m", True),
)
#: the unit of each number of a rig file (its [rig] table's, the covariance ``moi calibrate`` writes, [sensor]'s and
#: [object]'s): what a page writes beside them
RIG_UNITS: dict[str, str] = {**{name: unit for name, unit, _ in _RIG_NUMBERS},
                             "stiffness_tare_covariance": "N·m/rad·kg·m²", "clock_accuracy_ppm": "ppm",
                             "axis_offset": "m", "axis_offset_std": "m"}


def _rig_table(doc: Mapping[str, Any]) -> Mapping[str, Any]:
    """The rig file's [rig] table, its keys and kind known; its tables known."""
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
        raise RigError(f"rig file: [rig] kind is missing; expected one of {', '.join(RIG_KINDS)}")
    if rig["kind"] not in RIG_KINDS:
        raise RigError(f"rig file: unknown kind {rig['kind']!r}; expected one of {', '.join(RIG_KINDS)}")
    return rig


def _reproducibility(doc: Mapping[str, Any]) -> tuple[float | None, int | None]:
    """[calibration]'s reproducibility (relative 1σ of ω_n) and its degrees of freedom: both or neither."""
    if not set(doc) & _REPRO_KEYS:
        return None, None
    rel, dof = doc.get("reproducibility"), doc.get("reproducibility_dof")
    if not set(doc) >= _REPRO_KEYS or isinstance(dof, bool) or not isinstance(dof, int) or dof < 1:
        raise RigError(f"rig file: [calibration] reproducibility needs reproducibility_dof, a whole number >= 1 "
                       f"(Σ(n_i − 1) of the releases pooled), got {dof!r}")
    return _positive("[calibration] reproducibility", rel, "(a relative 1σ of ω_n)"), dof


def _object_transfer(o: Any) -> ObjectTransfer:
    """The rig file's [object] table."""
    if not isinstance(o, Mapping) or not set(o) >= _OBJECT_KEYS or set(o) - _OBJECT_KEYS - _OBJECT_STD_KEYS:
        raise RigError("rig file: [object] needs mass (kg) and axis_offset (m), optionally mass_std (kg) "
                       "and axis_offset_std (m)")
    return ObjectTransfer(
        mass=_positive("object.mass", o["mass"], "kg"),
        axis_offset=_positive("object.axis_offset", o["axis_offset"], "m", allow_zero=True),
        mass_std=None if "mass_std" not in o else _positive("object.mass_std", o["mass_std"], "kg", allow_zero=True),
        axis_offset_std=None if "axis_offset_std" not in o else _positive(
            "object.axis_offset_std", o["axis_offset_std"], "m", allow_zero=True),
    )


def _declared(m: Any) -> tuple[str, ...]:
    """The effects the rig file's [model] table declares."""
    if not isinstance(m, Mapping) or set(m) - _MODEL_KEYS:
        raise RigError("rig file: [model] takes only declared = [effect names]")
    d = m.get("declared", [])
    if not isinstance(d, list) or not all(isinstance(x, str) for x in d):
        raise RigError("rig file: [model] declared must be a list of effect names")
    return tuple(d)


def _sensor(sensor: Any) -> tuple[bool, Mapping[str, Any]]:
    """(whether the sensor is calibrated, the rig file's [sensor] table)."""
    if not isinstance(sensor, Mapping) or set(sensor) - _SENSOR_KEYS:
        raise RigError("rig file: [sensor] takes only calibrated = true | false, clock_accuracy_ppm "
                       "(1σ, ppm) and angle_scale_std (1σ, relative)")
    calibrated = sensor.get("calibrated", False)
    if not isinstance(calibrated, bool):
        raise RigError(f"rig file: [sensor] calibrated must be true or false, got {calibrated!r}")
    return calibrated, sensor
