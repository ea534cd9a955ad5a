"""The identification result: one plain, complete, serialisable object.

The JSON of ``moi identify --json``, the MQTT payload and the Modbus
registers are all produced from this object (``to_dict``), so they cannot
disagree. Arrays (trace, fit, residuals) stay on the object for plots and the
result store and are left out of ``to_dict`` unless asked for.

Typed all the way down: the model's form (``ModelForm``), the uncertainty
budgets (``measurement.uncertainty.Budget``) and the residual's diagnostics
(``measurement.residual.Diagnostics``) are objects, and ``from_dict`` reads a
result JSON of this schema back into the same object (a number the JSON cannot
hold, NaN or ±∞, is written null and read back NaN): ``to_dict`` of what
``from_dict`` read is the JSON it read.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from . import flags as F
from .errors import ResultSchemaError
from .periods import Periods
from .reproducibility import Reproducibility
from .residual import Diagnostics
from .uncertainty import Budget
from .wire import read_number

#: the version of the keys of ``IdentificationResult.to_dict()``; what each version changed is in CHANGELOG.md
SCHEMA_VERSION = 9


def _num(v: Any) -> Any:
    if v is None:
        return None
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    return v


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    return _num(v)


#: two-sided p-value below which the halves' ω_n disagree (the model does not hold across the record)
DISAGREE_P = 0.01


@dataclass(frozen=True)
class SegmentCheck:
    """The final model fitted to each half of the record (``measurement.consistency.check_segments``).

    omega_n / omega_n_std: per half, rad/s. z: |ω₁ − ω₂| over their combined
    σ; p: its two-sided p-value. u: the model-form standard uncertainty of
    ω_n (rad/s) from the halves' scatter about the whole record's value
    beyond their own σ (0 when they scatter no more than that), the larger
    of the halves' and of the second half's with the first refitted from
    t_free (s), its first half-swing (the release) left out: ω_n_free ±
    omega_n_std_free there (None: too short to be fitted without it).
    """

    t_split: float
    omega_n: tuple[float, ...]
    omega_n_std: tuple[float, ...]
    z: float
    p: float
    u: float
    t_free: float | None = None
    omega_n_free: float | None = None
    omega_n_std_free: float | None = None

    @property
    def disagree(self) -> bool:
        return self.p < DISAGREE_P

    def to_dict(self) -> dict[str, Any]:
        return {"t_split": _num(self.t_split), "omega_n": [_num(w) for w in self.omega_n],
                "omega_n_std": [_num(s) for s in self.omega_n_std], "z": _num(self.z), "p": _num(self.p),
                "u": _num(self.u), "disagree": self.disagree, "t_free": _num(self.t_free),
                "omega_n_free": _num(self.omega_n_free), "omega_n_std_free": _num(self.omega_n_std_free)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SegmentCheck:
        """Read back ``to_dict`` (``disagree`` is the property that computes it)."""
        return cls(read_number(d["t_split"]), tuple(read_number(w) for w in d["omega_n"]),
                   tuple(read_number(s) for s in d["omega_n_std"]), read_number(d["z"]), read_number(d["p"]),
                   read_number(d["u"]), *(None if d.get(k) is None else read_number(d[k])
                                          for k in ("t_free", "omega_n_free", "omega_n_std_free")))


@dataclass(frozen=True)
class Competitor:
    """A model the data do not decisively separate from the one kept.

    change: what differs from the kept model, in words; d_bic: its BIC
    minus the kept model's (under the noise model); weight: its BIC weight
    in its round; omega_n: its ω_n, rad/s; delta: minus the kept model's ω_n
    in the same round, rad/s; effects: the rival model's effects where it is a
    whole model of its own (an effect withdrawn, a law in an effect's place),
    so that several releases together can weigh it again; empty otherwise.
    """

    change: str
    d_bic: float
    weight: float
    omega_n: float
    delta: float
    effects: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"change": self.change, "d_bic": _num(self.d_bic), "weight": _num(self.weight),
                "omega_n": _num(self.omega_n), "delta": _num(self.delta), "effects": list(self.effects)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Competitor:
        """Read back ``to_dict``."""
        return cls(d["change"], read_number(d["d_bic"]), read_number(d["weight"]), read_number(d["omega_n"]),
                   read_number(d["delta"]), tuple(d["effects"]))


@dataclass(frozen=True)
class ModelForm:
    """The model-form part of ω_n's uncertainty: segments and competing explanations (rad/s)."""

    segments: SegmentCheck | None
    competitors: tuple[Competitor, ...]
    u_competitors: float

    @property
    def u_segments(self) -> float:
        return 0.0 if self.segments is None else self.segments.u

    @property
    def u(self) -> float:
        return math.hypot(self.u_segments, self.u_competitors)

    def ambiguous(self, omega_n_std: float) -> bool:
        """Rival models within the margin spread ω_n by more than the fit's σ (rad/s) says."""
        return self.u_competitors > omega_n_std

    def to_dict(self) -> dict[str, Any]:
        return {"u": _num(self.u), "u_segments": _num(self.u_segments), "u_competitors": _num(self.u_competitors),
                "segments": None if self.segments is None else self.segments.to_dict(),
                "competitors": [c.to_dict() for c in self.competitors]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ModelForm:
        """Read back ``to_dict`` (``u`` and ``u_segments`` are the properties that compute them)."""
        segments = None if d["segments"] is None else SegmentCheck.from_dict(d["segments"])
        return cls(segments, tuple(Competitor.from_dict(c) for c in d["competitors"]), read_number(d["u_competitors"]))


#: where ω_n is read: the small-swing limit of the rig's own law (compound, wire suspensions), or at a swing
#: amplitude on a torsion rig, the calibration's or the record's own (``identification.measurand``)
LIMIT, CALIBRATION, RECORD, RELEASES = "small-swing limit", "calibration", "record", "releases"


@dataclass(frozen=True)
class ReadAt:
    """The swing amplitude ω_n (and J) is read at.

    amplitude: rad (0: the small-swing limit); basis: LIMIT, CALIBRATION (the amplitude the rig's calibration
    read its references at), RECORD (the record's own: the amplitude a damped sinusoid fitted to it measures
    at) or RELEASES (the releases of one object read together, at their own amplitudes' mean); limit, limit_std: where a fitted amplitude law is read at the amplitude, the law's small-swing limit and
    its 1σ, rad/s (None: no such law, ω_n is the same at every amplitude the model knows).
    """

    amplitude: float = 0.0
    basis: str = LIMIT
    limit: float | None = None
    limit_std: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"amplitude": _num(self.amplitude), "basis": self.basis, "limit": _num(self.limit),
                "limit_std": _num(self.limit_std)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ReadAt:
        """Read back ``to_dict``."""
        return cls(read_number(d["amplitude"]), str(d["basis"]), d["limit"], d["limit_std"])

    def describe(self) -> str:
        """The measurand in words, for the report."""
        if self.basis == LIMIT:
            return "ω_n is the small-swing limit of the rig's restoring law"
        if self.amplitude <= 0:
            return "ω_n is the small-swing limit: the rig's calibration read its references at zero amplitude"
        where = {CALIBRATION: "the amplitude the rig's calibration read its references at",
                 RELEASES: "the mean of the object's releases' own amplitudes (one measurand for the releases together)",
                 }.get(self.basis, "the record's own amplitude, where a damped sinusoid fitted to it measures")
        law = ("" if self.limit is None else
               f"; the fitted amplitude law's small-swing limit, {self.limit:.6g} ± {self.limit_std or 0.0:.2g} rad/s, "
               "is not J's (a free law is not extrapolated to zero amplitude)")
        return f"ω_n is the frequency at a swing of {self.amplitude:.3g} rad, {where}{law}"


@dataclass(frozen=True)
class Quantity:
    """A value with its 1σ standard uncertainty and SI unit (value None = unknown)."""

    value: float | None
    std: float | None
    unit: str

    def to_dict(self) -> dict[str, Any]:
        return {"value": _num(self.value), "std": _num(self.std), "unit": self.unit}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Quantity:
        """Read back ``to_dict``."""
        return cls(d["value"], d["std"], d["unit"])

    def __str__(self) -> str:
        if self.value is None:
            return f"n/a ({self.unit})"
        if self.std is None or not math.isfinite(self.std):
            return f"{self.value:.6g} {self.unit}"
        return f"{self.value:.7g} ± {self.std:.2g} {self.unit}"


@dataclass(frozen=True)
class ModelSummary:
    """What one model (the declared one, or the final one) says."""

    effects: tuple[str, ...]
    J: float | None
    J_std: float | None
    omega_n: float
    omega_n_std: float
    residual_rms: float
    bic: float
    aic: float
    damping: dict[str, dict[str, Quantity]]

    def to_dict(self) -> dict[str, Any]:
        return {
            "effects": list(self.effects),
            "J": _num(self.J), "J_std": _num(self.J_std),
            "omega_n": _num(self.omega_n), "omega_n_std": _num(self.omega_n_std),
            "residual_rms": _num(self.residual_rms),
            "bic": _num(self.bic), "aic": _num(self.aic),
            "damping": {e: {k: q.to_dict() for k, q in ps.items()} for e, ps in self.damping.items()},
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ModelSummary:
        """Read back ``to_dict``."""
        return cls(tuple(d["effects"]), d["J"], d["J_std"], read_number(d["omega_n"]), read_number(d["omega_n_std"]),
                   read_number(d["residual_rms"]), read_number(d["bic"]), read_number(d["aic"]),
                   quantities_from_dict(d["damping"]))


def quantities_from_dict(d: Mapping[str, Any]) -> dict[str, dict[str, Quantity]]:
    """effect → parameter → ``Quantity``, read back from its JSON."""
    return {e: {k: Quantity.from_dict(q) for k, q in ps.items()} for e, ps in d.items()}


@dataclass(frozen=True)
class DiscoveryStep:
    """One round of the discovery loop and its evidence.

    candidates: effect → {bic, residual_rms, excess_explained} for every effect tried.
    chosen: the effect added this round, or None when none helped (the loop stopped).
    evidence: the diagnostics that pointed to the chosen effect, in words.
    """

    round: int
    residual_rms_before: float
    bic_before: float
    candidates: dict[str, dict[str, float]]
    chosen: str | None
    residual_rms_after: float | None
    bic_after: float | None
    evidence: str
    reason: str
    #: ω_n of the model the round started from, rad/s
    omega_n_before: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "round": self.round,
            "residual_rms_before": _num(self.residual_rms_before), "bic_before": _num(self.bic_before),
            "omega_n_before": _num(self.omega_n_before),
            "candidates": {k: {kk: _num(vv) for kk, vv in v.items()} for k, v in self.candidates.items()},
            "chosen": self.chosen,
            "residual_rms_after": _num(self.residual_rms_after), "bic_after": _num(self.bic_after),
            "evidence": self.evidence, "reason": self.reason,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DiscoveryStep:
        """Read back ``to_dict``."""
        return cls(d["round"], read_number(d["residual_rms_before"]), read_number(d["bic_before"]),
                   {k: dict(v) for k, v in d["candidates"].items()}, d["chosen"], d["residual_rms_after"],
                   d["bic_after"], d["evidence"], d["reason"], d["omega_n_before"])


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """Everything a measurement says. SI units; *_std are 1σ standard uncertainties.

    J: total inertia about the pivot, kg·m² (None when the rig lacks k or m·S); J_std: the fit's 1σ alone.
    J_object: J − tare_inertia (None without a tare); J_object_std: the fit's σ ⊕ the tare's, a display
    figure without the k–I0 correlation. J_object_axis: the parallel-axis transfer J_object − m·L² about
    the object's own axis.
    uncertainty_budget: measurand → its GUM budget, the one uncertainty of J, J_object and J_object_axis a
    decision uses (``measurement.verdict.Reading.from_result``): its u split into random and systematic,
    its coverage factor and U. J_u, J_U, coverage_factor and, in ``to_dict``, J_object_u / _U and
    J_object_axis_u / _U are read from it.
    omega_n: small-amplitude natural angular frequency, rad/s.
    damping_ratio: equivalent viscous damping ratio at ``reference_amplitude``.
    residual_rms / noise_floor: rad; baseline: the declared model's summary.
    """

    source: str
    rig_kind: str
    J: float | None
    J_std: float | None
    J_object: float | None
    J_object_std: float | None
    J_object_axis: float | None
    J_object_axis_std: float | None
    omega_n: float
    omega_n_std: float
    #: 1σ of ω_n from a sensor calibration made on the record (the camera view measured from two markers), rad/s
    omega_n_std_calibration: float | None
    damping_ratio: float
    damping_ratio_std: float
    reference_amplitude: float
    offset: Quantity
    damping: dict[str, dict[str, Quantity]]
    stiffness: dict[str, dict[str, Quantity]]
    sensor: dict[str, dict[str, Quantity]]
    declared_effects: tuple[str, ...]
    effects: tuple[str, ...]
    added_effects: tuple[str, ...]
    residual_rms: float
    noise_floor: float
    statistics: dict[str, Any]
    flags: tuple[str, ...]
    baseline: ModelSummary
    steps: tuple[DiscoveryStep, ...]
    #: the final residual's (``measurement.residual``)
    diagnostics: Diagnostics
    structure: tuple[str, ...]
    window: dict[str, Any]
    #: facts from the sensor path (camera yaw, dropped frames, encoder errors...), from Trace.meta
    acquisition: dict[str, Any] = field(default_factory=dict)
    #: the rig declared the angle sensor calibrated: no effect fitted the angle's scale
    sensor_calibrated: bool = False
    #: 1σ of ω_n (rad/s) from the model's form: the record's halves scattering beyond their σ, and rival
    #: models the data do not decisively separate (``model_form`` says which)
    omega_n_std_model: float = 0.0
    #: combined standard uncertainty of ω_n (rad/s): fit ⊕ camera view calibration ⊕ model form
    omega_n_u: float | None = None
    #: the halves of the record and the rival models
    model_form: ModelForm = field(default_factory=lambda: ModelForm(None, (), 0.0))
    #: measurand ("J", "J_object", "J_object_axis") → its GUM budget (``measurement.uncertainty.Budget``):
    #: lines (source, value, u, sensitivity, contribution, share), u, coverage factor, U
    uncertainty_budget: dict[str, Budget] = field(default_factory=dict)
    #: what the sensor read: "angle" (rad) or "rate" (rad/s, a gyro: offset and the arrays' "angle" are then rates)
    measures: str = "angle"
    #: the small-swing period, the period at the record's amplitude and as counted, g (None: not computed)
    periods: Periods | None = None
    #: the model ω_n (and J) is read from: "discovered" (the final model, ``effects``) or "declared" (the
    #: declared model, where its ω_n is the more accurate: ``identification.focus``), and its effects
    omega_n_from: str = "discovered"
    omega_n_effects: tuple[str, ...] = ()
    #: the scatter of ω_n between releases, which one record cannot see (``measurement.reproducibility``):
    #: a rig's history pooled, its calibration's figure, or the documented default (each in u); None: not said
    reproducibility: Reproducibility | None = None
    #: the swing amplitude ω_n and J are read at (``ReadAt``; schema 9)
    omega_n_read_at: ReadAt = field(default_factory=ReadAt)
    arrays: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def error_reduction(self) -> float | None:
        """Fraction by which the final model lowered the declared model's residual RMS."""
        if self.baseline.residual_rms > 0:
            return 1.0 - self.residual_rms / self.baseline.residual_rms
        return None

    def _budget(self, measurand: str, key: str) -> float | None:
        b = self.uncertainty_budget.get(measurand)
        return None if b is None else _num(getattr(b, key))

    @property
    def J_u(self) -> float | None:
        """Combined standard uncertainty of J, kg·m² (the budget's: fit ⊕ model form ⊕ calibration ⊕ rig)."""
        return self._budget("J", "u")

    @property
    def J_U(self) -> float | None:
        """Expanded uncertainty of J, kg·m² (coverage factor in the budget)."""
        return self._budget("J", "U")

    @property
    def coverage_factor(self) -> float | None:
        """k of J_U = k·J_u (2 unless the effective degrees of freedom call for more)."""
        return self._budget("J", "coverage_factor")

    def to_dict(self, include_arrays: bool = False) -> dict[str, Any]:
        d: dict[str, Any] = {
            "schema": SCHEMA_VERSION,
            "source": self.source,
            "rig_kind": self.rig_kind,
            "J": _num(self.J), "J_std": _num(self.J_std),
            "J_object": _num(self.J_object), "J_object_std": _num(self.J_object_std),
            "J_object_axis": _num(self.J_object_axis), "J_object_axis_std": _num(self.J_object_axis_std),
            "omega_n": _num(self.omega_n), "omega_n_std": _num(self.omega_n_std),
            "omega_n_std_calibration": _num(self.omega_n_std_calibration),
            "omega_n_std_model": _num(self.omega_n_std_model), "omega_n_u": _num(self.omega_n_u),
            "J_u": self.J_u, "J_U": self.J_U, "coverage_factor": self.coverage_factor,
            "J_object_u": self._budget("J_object", "u"), "J_object_U": self._budget("J_object", "U"),
            "J_object_axis_u": self._budget("J_object_axis", "u"),
            "J_object_axis_U": self._budget("J_object_axis", "U"),
            "uncertainty_budget": _jsonable({k: b.to_dict() for k, b in self.uncertainty_budget.items()}),
            "model_form": _jsonable(self.model_form.to_dict()),
            "damping_ratio": _num(self.damping_ratio), "damping_ratio_std": _num(self.damping_ratio_std),
            "reference_amplitude": _num(self.reference_amplitude),
            "offset": self.offset.to_dict(),
            "declared_effects": list(self.declared_effects),
            "effects": list(self.effects),
            "added_effects": list(self.added_effects),
            "damping": {e: {k: q.to_dict() for k, q in ps.items()} for e, ps in self.damping.items()},
            "stiffness": {e: {k: q.to_dict() for k, q in ps.items()} for e, ps in self.stiffness.items()},
            "sensor": {e: {k: q.to_dict() for k, q in ps.items()} for e, ps in self.sensor.items()},
            "residual_rms": _num(self.residual_rms),
            "noise_floor": _num(self.noise_floor),
            "error_reduction": _num(self.error_reduction),
            "statistics": {k: _num(v) for k, v in self.statistics.items()},
            "flags": list(self.flags),
            "warnings": list(F.warnings(self.flags)),
            "baseline": self.baseline.to_dict(),
            "steps": [s.to_dict() for s in self.steps],
            "diagnostics": {k: _num(v) for k, v in self.diagnostics.as_dict().items()},
            "structure": list(self.structure),
            "window": {k: _num(v) for k, v in self.window.items()},
            "acquisition": _jsonable(self.acquisition),
            "sensor_calibrated": self.sensor_calibrated,
            "measures": self.measures,
            "periods": None if self.periods is None else self.periods.to_dict(),
            "omega_n_from": self.omega_n_from,
            "omega_n_effects": list(self.omega_n_effects or self.effects),
            "reproducibility": None if self.reproducibility is None else self.reproducibility.to_dict(),
            "omega_n_read_at": self.omega_n_read_at.to_dict(),
        }
        if include_arrays:
            d["arrays"] = {k: [_num(x) for x in np.asarray(v).tolist()] for k, v in self.arrays.items()}
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> IdentificationResult:
        """Read back ``to_dict`` of this schema (``SCHEMA_VERSION``; with ``arrays`` when it holds them).

        The keys ``to_dict`` derives (J_u, J_U, coverage_factor, J_object_u and _U, J_object_axis_u and _U,
        error_reduction, warnings) are the properties that compute them; keys beyond the result's (a payload's
        envelope) are not read. Raises ResultSchemaError for a result of another schema.
        """
        if d.get("schema") != SCHEMA_VERSION:
            raise ResultSchemaError(f"a result of schema {d.get('schema')!r}; expected schema {SCHEMA_VERSION}")
        optional = ("J", "J_std", "J_object", "J_object_std", "J_object_axis", "J_object_axis_std",
                    "omega_n_std_calibration", "omega_n_u")
        numbers = ("omega_n", "omega_n_std", "damping_ratio", "damping_ratio_std", "reference_amplitude",
                   "residual_rms", "noise_floor", "omega_n_std_model")
        return cls(
            source=d["source"], rig_kind=d["rig_kind"], **{k: d[k] for k in optional},
            **{k: read_number(d[k]) for k in numbers},
            offset=Quantity.from_dict(d["offset"]), damping=quantities_from_dict(d["damping"]),
            stiffness=quantities_from_dict(d["stiffness"]), sensor=quantities_from_dict(d["sensor"]),
            declared_effects=tuple(d["declared_effects"]), effects=tuple(d["effects"]),
            added_effects=tuple(d["added_effects"]), statistics=dict(d["statistics"]), flags=tuple(d["flags"]),
            baseline=ModelSummary.from_dict(d["baseline"]), steps=tuple(DiscoveryStep.from_dict(s) for s in d["steps"]),
            diagnostics=Diagnostics.from_dict(d["diagnostics"]), structure=tuple(d["structure"]),
            window=dict(d["window"]), acquisition=dict(d["acquisition"]), sensor_calibrated=d["sensor_calibrated"],
            measures=d["measures"],
            periods=None if d.get("periods") is None else Periods.from_dict(d["periods"]),
            omega_n_from=d.get("omega_n_from", "discovered"),
            omega_n_effects=tuple(d.get("omega_n_effects") or d["effects"]),
            model_form=ModelForm.from_dict(d["model_form"]),
            reproducibility=None if d.get("reproducibility") is None else Reproducibility.from_dict(d["reproducibility"]),
            omega_n_read_at=ReadAt.from_dict(d["omega_n_read_at"]),
            uncertainty_budget={k: Budget.from_dict(b) for k, b in d["uncertainty_budget"].items()},
            arrays={k: np.asarray(v, dtype=float) for k, v in (d.get("arrays") or {}).items()},
        )

    def to_json(self, **kwargs: Any) -> str:
        return json.dumps(self.to_dict(**kwargs), ensure_ascii=False, allow_nan=False)
