"""The identification result: one plain, complete, serialisable object.

The JSON of ``moi identify --json``, the MQTT payload and the Modbus
registers are all produced from this object (``to_dict``), so they cannot
disagree. Arrays (trace, fit, residuals) stay on the object for plots and the
result store and are left out of ``to_dict`` unless asked for.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: the version of the keys of ``IdentificationResult.to_dict()``; what each version changed is in CHANGELOG.md
SCHEMA_VERSION = 5


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


def _budget_table(b: dict[str, Any]) -> list[str]:
    """A budget dict (``measurement.uncertainty.Budget.to_dict``) as the report's table."""
    out = [f"    {'source':<32}{'value':>12}{'u':>10}  {'unit':<8}{'c':>10}{'c·u':>10}{'share':>8}"]
    for ln in b["lines"]:
        note = f"  ({ln['note']})" if ln.get("note") else ""
        value = ln["value"] if ln["value"] is not None else float("nan")
        c = ln["sensitivity"] if ln["sensitivity"] is not None else float("nan")
        out.append(f"    {ln['source'][:32]:<32}{value:>12.6g}{ln['std']:>10.2g}  {ln['unit']:<8}{c:>10.3g}"
                   f"{ln['contribution']:>10.2g}{100 * ln['share']:>7.1f}%{note}")
    for c in b.get("correlations", ()):
        out.append(f"    correlation r({c['a']}, {c['b']}) = {c['r']:+.4f}: {100 * b['correlation_share']:+.1f} % of u²")
    dof = "∞" if b.get("dof") is None else f"{b['dof']:.0f}"
    rel = f" ({100 * b['U'] / abs(b['value']):.3g} %)" if b.get("value") else ""
    out.append(f"    u = {b['u']:.3g} {b['unit']}, ν_eff = {dof}, k = {b['coverage_factor']:.2f}, "
               f"U = {b['U']:.3g} {b['unit']}{rel}")
    return out


@dataclass(frozen=True)
class Quantity:
    """A value with its 1σ standard uncertainty and SI unit (value None = unknown)."""

    value: float | None
    std: float | None
    unit: str

    def to_dict(self) -> dict[str, Any]:
        return {"value": _num(self.value), "std": _num(self.std), "unit": self.unit}

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


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """Everything a measurement says. SI units; *_std are 1σ standard uncertainties.

    J: total inertia about the pivot, kg·m² (None when the rig lacks k or m·S).
    J_object: J − tare_inertia (None without a tare); J_object_std: the fit's σ ⊕ the tare's, as before
    (kept for old readers); J_object_u / J_object_U (``to_dict``): the budget's, the k–I0 correlation kept.
    J_object_axis: the parallel-axis transfer J_object − m·L² about the object's own axis.
    omega_n: small-amplitude natural angular frequency, rad/s.
    damping_ratio: equivalent viscous damping ratio at ``reference_amplitude``.
    residual_rms / noise_floor: rad; baseline: the declared model's summary.
    """

    source: str
    rig_kind: str
    J: float | None
    J_std: float | None
    J_std_calibration: float | None
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
    diagnostics: dict[str, Any]
    structure: tuple[str, ...]
    window: dict[str, Any]
    #: facts from the sensor path (camera yaw, dropped frames, encoder errors...), from Trace.meta
    acquisition: dict[str, Any] = field(default_factory=dict)
    #: the rig declared the angle sensor calibrated: no effect fitted the angle's scale
    sensor_calibrated: bool = False
    #: 1σ of ω_n (rad/s) and J (kg·m²) from the model's form: the record's halves scattering beyond
    #: their σ, and rival models the data do not decisively separate (``model_form`` says which)
    omega_n_std_model: float = 0.0
    J_std_model: float | None = None
    #: combined standard uncertainty of ω_n (rad/s) and J (kg·m²): fit ⊕ calibration ⊕ model form
    omega_n_u: float | None = None
    J_u: float | None = None
    model_form: dict[str, Any] = field(default_factory=dict)
    #: measurand ("J", "J_object", "J_object_axis") → its GUM budget (``measurement.uncertainty.Budget.to_dict``):
    #: lines (source, value, u, sensitivity, contribution, share), u, coverage factor, U
    uncertainty_budget: dict[str, Any] = field(default_factory=dict)
    #: what the sensor read: "angle" (rad) or "rate" (rad/s, a gyro: offset and the arrays' "angle" are then rates)
    measures: str = "angle"
    arrays: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def error_reduction(self) -> float | None:
        """Fraction by which the final model lowered the declared model's residual RMS."""
        if self.baseline.residual_rms > 0:
            return 1.0 - self.residual_rms / self.baseline.residual_rms
        return None

    def _budget(self, measurand: str, key: str) -> float | None:
        b = self.uncertainty_budget.get(measurand)
        return None if b is None else _num(b.get(key))

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
            "J_std_calibration": _num(self.J_std_calibration),
            "J_object": _num(self.J_object), "J_object_std": _num(self.J_object_std),
            "J_object_axis": _num(self.J_object_axis), "J_object_axis_std": _num(self.J_object_axis_std),
            "omega_n": _num(self.omega_n), "omega_n_std": _num(self.omega_n_std),
            "omega_n_std_calibration": _num(self.omega_n_std_calibration),
            "omega_n_std_model": _num(self.omega_n_std_model), "omega_n_u": _num(self.omega_n_u),
            "J_std_model": _num(self.J_std_model), "J_u": _num(self.J_u),
            "J_U": self.J_U, "coverage_factor": self.coverage_factor,
            "J_object_u": self._budget("J_object", "u"), "J_object_U": self._budget("J_object", "U"),
            "J_object_axis_u": self._budget("J_object_axis", "u"),
            "J_object_axis_U": self._budget("J_object_axis", "U"),
            "uncertainty_budget": _jsonable(self.uncertainty_budget),
            "model_form": _jsonable(self.model_form),
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
            "baseline": self.baseline.to_dict(),
            "steps": [s.to_dict() for s in self.steps],
            "diagnostics": {k: _num(v) for k, v in self.diagnostics.items()},
            "structure": list(self.structure),
            "window": {k: _num(v) for k, v in self.window.items()},
            "acquisition": _jsonable(self.acquisition),
            "sensor_calibrated": self.sensor_calibrated,
            "measures": self.measures,
        }
        if include_arrays:
            d["arrays"] = {k: [_num(x) for x in np.asarray(v).tolist()] for k, v in self.arrays.items()}
        return d

    def to_json(self, **kwargs: Any) -> str:
        return json.dumps(self.to_dict(**kwargs), ensure_ascii=False, allow_nan=False)

    # -- readable report -------------------------------------------------------
    def report(self) -> str:
        """A plain-text report for the technician (lmfit ``fit_report`` style)."""
        L: list[str] = []
        s = self.statistics
        L.append(f"[[Identification]] {self.source}  ({self.rig_kind} rig)")
        L.append(f"    samples {s.get('n')}, window {self.window.get('t_start', 0):.3f}–{self.window.get('t_stop', 0):.3f} s,"
                 f" {s.get('nfev')} simulations, converged: {s.get('success')}")
        L.append("[[Result]]")
        def expanded(measurand: str) -> str:
            b = self.uncertainty_budget.get(measurand)
            return "" if not b else f"; U = {b['U']:.2g} kg·m² (k = {b['coverage_factor']:.3g}, budget below)"

        if self.J is not None:
            extra = f" (calibration adds ±{self.J_std_calibration:.2g})" if self.J_std_calibration else ""
            L.append(f"    J            = {Quantity(self.J, self.J_std, 'kg·m²')}{extra}{expanded('J')}")
        else:
            L.append("    J            = n/a: the rig gives no stiffness (torsion) or mass·com_distance (compound)")
        if self.J_object is not None:
            L.append(f"    J_object     = {Quantity(self.J_object, self.J_object_std, 'kg·m²')}  (J − tare)"
                     f"{expanded('J_object')}")
        if self.J_object_axis is not None:
            L.append(f"    J_object_axis= {Quantity(self.J_object_axis, self.J_object_axis_std, 'kg·m²')}  (own axis, J_D − m·L²)"
                     f"{expanded('J_object_axis')}")
        cal = (f"; the camera view's calibration adds ±{self.omega_n_std_calibration:.2g}"
               if self.omega_n_std_calibration else "")
        L.append(f"    omega_n      = {Quantity(self.omega_n, self.omega_n_std, 'rad/s')}"
                 f"  (f_n = {self.omega_n / (2 * math.pi):.6g} Hz{cal})")
        if self.omega_n_std_model:
            ju = f"; J ± {self.J_u:.2g} kg·m²" if self.J_u is not None else ""
            L.append(f"    model form   = ±{self.omega_n_std_model:.2g} rad/s (halves of the record, rival models)"
                     f" → combined u: ω_n ± {self.omega_n_u:.2g} rad/s{ju}")
        for measurand, b in self.uncertainty_budget.items():
            L.append(f"[[Uncertainty budget]] {measurand} (GUM; J_std above is the fit's 1σ alone)")
            L.extend(_budget_table(b))
        L.append(f"    damping ratio= {Quantity(self.damping_ratio, self.damping_ratio_std, '')}"
                 f" (equivalent viscous, at {self.reference_amplitude:.4g} rad)")
        for group in (self.damping, self.stiffness, self.sensor):
            for eff, params in group.items():
                for name, q in params.items():
                    if q.value is not None:
                        L.append(f"    {eff}.{name:<10} = {q}")
        L.append(f"    offset       = {self.offset}")
        L.append("[[Model]]")
        L.append(f"    declared : {', '.join(self.declared_effects) or '(none)'}")
        L.append(f"    final    : {', '.join(self.effects) or '(none)'}")
        L.append(f"    added    : {', '.join(self.added_effects) or '(none)'}")
        if self.sensor_calibrated:
            L.append("    sensor   : calibrated (its scale is known: effects that fit it, gain and view, not offered)")
        L.append("[[Before / after]]")
        b = self.baseline
        jb = f"{b.J:.7g}" if b.J is not None else "n/a"
        ja = f"{self.J:.7g}" if self.J is not None else "n/a"
        L.append(f"    {'':14}{'declared':>16}{'final':>16}")
        L.append(f"    {'J [kg·m²]':14}{jb:>16}{ja:>16}")
        L.append(f"    {'omega_n [rad/s]':14}{b.omega_n:>15.7g}{self.omega_n:>16.7g}")
        L.append(f"    {'residual [rad]':14}{b.residual_rms:>16.4g}{self.residual_rms:>16.4g}")
        L.append(f"    {'BIC':14}{b.bic:>16.1f}{s.get('bic', float('nan')):>16.1f}")
        L.append(f"    noise floor {self.noise_floor:.3g} rad; residual/noise {self.residual_rms / self.noise_floor if self.noise_floor else float('nan'):.3g};"
                 f" error reduction {100 * (self.error_reduction or 0):.1f} %")
        if self.steps:
            L.append("[[Discovery]]")
            for st in self.steps:
                tried = ", ".join(f"{k} ΔBIC {v['bic'] - st.bic_before:+.1f}" for k, v in st.candidates.items())
                if st.chosen:
                    L.append(f"    round {st.round}: added {st.chosen} — {st.reason}")
                    if st.evidence:
                        L.append(f"        evidence: {st.evidence}")
                else:
                    L.append(f"    round {st.round}: nothing added — {st.reason}")
                if tried:
                    L.append(f"        tried: {tried}")
        L.append("[[Residual]]")
        for line in self.structure:
            L.append(f"    {line}")
        if self.acquisition:
            L.append("[[Acquisition]]")

            def walk(prefix: str, value: Any) -> None:
                if isinstance(value, dict):
                    for k, v in value.items():
                        walk(f"{prefix}.{k}" if prefix else str(k), v)
                elif isinstance(value, float):
                    L.append(f"    {prefix} = {value:.6g}")
                else:
                    L.append(f"    {prefix} = {value}")

            walk("", self.acquisition)
        L.append(f"[[Flags]] {', '.join(self.flags) if self.flags else 'none'}")
        return "\n".join(L)
