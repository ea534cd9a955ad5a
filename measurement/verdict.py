"""Conformity decisions: OK / NOK / INVALID for one release and for a part measured N times.

Pure and hardware-free: numbers in, a decision object out. SI units; the
measurand is J, J_object or J_object_axis of a result (kg·m²).

The decision rule (ISO 14253-1:2017, "Geometrical product specifications —
Inspection by measurement of workpieces and measuring equipment — Part 1:
Decision rules for verifying conformity or nonconformity with specifications")
------------------------------------------------------------------------------
Specification zone: LSL ≤ x ≤ USL (a recipe gives nominal ± tolerance).
U = k·u_c is the expanded uncertainty (coverage factor k, default 2 ≈ 95 %,
more when the effective degrees of freedom are few: Welch–Satterthwaite),
u_c the combined standard uncertainty of the part's value from the result's
GUM budget (``measurement.uncertainty``): the random part (identification
fit, model form, repeatability of the releases) and the systematic part
common to every release (calibration of k with I0 and their correlation, the
rig's m, g, S, the clock, the sensor's scale...).

* ``guard_band`` (default): conformance is proven only when the whole
  uncertainty interval lies in the zone, LSL + U ≤ x ≤ USL − U → OK;
  nonconformance is proven when it lies wholly outside, x < LSL − U or
  x > USL + U → NOK; in between (the uncertainty range) the result proves
  neither, and the recipe's ``uncertain`` verdict applies: NOK by default (the
  supplier must prove conformance; an unproven part is rejected) or INVALID
  (measure again).
* ``simple``: OK when LSL ≤ x ≤ USL (shared risk; U is reported, not used).

A result is INVALID before any comparison when it cannot be trusted: a flag
the recipe names (a warning, ``measurement.flags``: e.g. ``fit_not_converged``,
``calibration_due``; by default none that only describes the residual), no value
(a rig without k), its standard uncertainty above the recipe's limit, fewer
swings than the recipe asks for, or an expanded uncertainty U above the
recipe's ``max_uncertainty_ratio`` of the half-tolerance (the test uncertainty
ratio: with 0.25, U may take at most a quarter of the tolerance's half-width).

Repeat measurements (``combine``)
---------------------------------
The part value is the mean of the usable releases, each weighed by its own
random uncertainty u_i (the fit's σ and the model-form term of its record:
a release whose model does not hold across its record counts for less; with
equal u_i it is the arithmetic mean). Its random standard uncertainty is the
larger of the Type A standard deviation of the mean s/√n (GUM 4.2.3) and the
releases' own uncertainties propagated through the weighted mean
1/√(Σ1/u_i²): with n = 3 the Type A estimate has 2 degrees of freedom and
may come out far too small by chance; when the Type A term is the larger, its
n − 1 degrees of freedom enter the coverage factor (Welch–Satterthwaite,
Student's t at 95.45 %). The systematic part (the calibration) is common to
all releases and does not average down; it is added in quadrature once.

With the releases' identifications at hand (the appliance), the part's value
is their joint identification instead (``measurement.joint``: the physics
shared, each release's offset and sensor terms its own, the releases weighed
by their whole uncertainty and the joint σ scaled by the Birge ratio when they
scatter beyond it); the Type A floor and the systematic part apply as above.

Agreement of the releases: release i is compared with the mean of the others,
z_i = (x_i − x̄_−i) / √(u_i² + u(x̄_−i)²), with u(x̄_−i) = √(Σ_{j≠i} u_j²)/(n−1).
With at least 3 usable releases, the one with the largest |z| above the
recipe's ``consistency_limit`` (default 3) is excluded and reported, once per
part; if the rest still disagree, or if 2 releases disagree (no way to tell
which one is wrong), the part is INVALID. Invalid releases are excluded with
their reasons. Fewer usable releases than ``min_valid_releases`` make the part
INVALID. Nothing is excluded silently: every exclusion is in ``excluded``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Sequence

from . import flags as F
from .errors import InvalidInput
from .uncertainty import coverage_factor as _coverage_factor
from .uncertainty import welch_satterthwaite

if TYPE_CHECKING:
    from .result import IdentificationResult

OK, NOK, INVALID = "OK", "NOK", "INVALID"

#: decision rules (see the module docstring)
RULES = ("guard_band", "simple")

#: what a result's ``J_*`` key means (the recipe's ``quantity``)
QUANTITIES = ("J", "J_object", "J_object_axis")

#: flags that make a result INVALID unless a recipe says otherwise: warnings only (``flags.GRADES``), never a
#: flag that describes the residual while its effect on ω_n is in the stated u
DEFAULT_INVALID_FLAGS = (F.FIT_NOT_CONVERGED, F.CALIBRATION_DUE, F.NEGATIVE_INERTIA)


class VerdictError(InvalidInput):
    """A specification or quality rule that cannot be used (says what was expected)."""


@dataclass(frozen=True)
class Specification:
    """What the part must be, and how conformity is decided.

    quantity: "J" | "J_object" | "J_object_axis". nominal, lower, upper: kg·m²
    (lower ≤ nominal ≤ upper). rule: "guard_band" | "simple". uncertain: the
    verdict in the uncertainty range of the guard-band rule ("NOK" | "INVALID").
    coverage_factor: k of U = k·u_c.
    """

    quantity: str
    nominal: float
    lower: float
    upper: float
    rule: str = "guard_band"
    uncertain: str = NOK
    coverage_factor: float = 2.0

    def __post_init__(self) -> None:
        if self.quantity not in QUANTITIES:
            raise VerdictError(f"quantity must be one of {', '.join(QUANTITIES)}, got {self.quantity!r}")
        if not all(math.isfinite(v) for v in (self.nominal, self.lower, self.upper)):
            raise VerdictError("nominal and limits must be finite numbers")
        if not self.lower < self.upper or not self.lower <= self.nominal <= self.upper:
            raise VerdictError(f"limits must satisfy lower < upper and lower <= nominal <= upper, got "
                               f"{self.lower:g} … {self.nominal:g} … {self.upper:g}")
        if self.rule not in RULES:
            raise VerdictError(f"decision rule must be one of {', '.join(RULES)}, got {self.rule!r}")
        if self.uncertain not in (NOK, INVALID):
            raise VerdictError(f"uncertain must be 'NOK' or 'INVALID', got {self.uncertain!r}")
        if not (math.isfinite(self.coverage_factor) and self.coverage_factor >= 1):
            raise VerdictError(f"coverage_factor must be >= 1, got {self.coverage_factor!r}")

    @classmethod
    def symmetric(cls, quantity: str, nominal: float, tolerance: float, **kwargs: Any) -> "Specification":
        """nominal ± tolerance (kg·m²)."""
        if not (math.isfinite(tolerance) and tolerance > 0):
            raise VerdictError(f"tolerance must be > 0, got {tolerance!r}")
        return cls(quantity, nominal, nominal - tolerance, nominal + tolerance, **kwargs)

    def to_dict(self) -> dict[str, Any]:
        return {"quantity": self.quantity, "nominal": self.nominal, "lower": self.lower, "upper": self.upper,
                "rule": self.rule, "uncertain": self.uncertain, "coverage_factor": self.coverage_factor}


@dataclass(frozen=True)
class QualityRules:
    """When a result is not trustworthy (INVALID), and how releases are combined.

    invalid_flags: result flags that make it INVALID. max_std: largest 1σ of the
    measurand, kg·m² (None: no limit). max_std_relative: the same relative to
    the value (None: no limit). min_swings: fewest full swings in the fitted
    window. consistency_limit: |z| above which releases disagree.
    min_valid_releases: fewest usable releases for a part verdict.
    max_uncertainty_ratio: largest U / half-tolerance (the inverse test uncertainty ratio, e.g. 0.25);
    None: no limit.
    """

    invalid_flags: tuple[str, ...] = DEFAULT_INVALID_FLAGS
    max_std: float | None = None
    max_std_relative: float | None = None
    min_swings: float = 3.0
    consistency_limit: float = 3.0
    min_valid_releases: int = 1
    max_uncertainty_ratio: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"invalid_flags": list(self.invalid_flags), "max_std": self.max_std,
                "max_std_relative": self.max_std_relative, "min_swings": self.min_swings,
                "consistency_limit": self.consistency_limit, "min_valid_releases": self.min_valid_releases,
                "max_uncertainty_ratio": self.max_uncertainty_ratio}


@dataclass(frozen=True)
class Reading:
    """One release's measurand (kg·m²) with its uncertainty split into random and systematic parts.

    value: None when the rig gives no J. u_random: 1σ of the identification.
    u_systematic: 1σ common to every release (calibration of k, tare).
    swings: full swings in the fitted window (ω_n·T/2π).
    coverage_factor: the k the result's budget calls for (None: the specification's).
    """

    value: float | None
    u_random: float | None
    u_systematic: float = 0.0
    flags: tuple[str, ...] = ()
    swings: float | None = None
    coverage_factor: float | None = None

    @classmethod
    def from_result(cls, result: IdentificationResult, quantity: str) -> "Reading":
        """One release's ``quantity`` with the uncertainty of its GUM budget (``result.uncertainty_budget``):
        its random lines (fit, model form) and the rest with their correlations (calibration, tare, rig,
        clock). A value without a budget has no stated uncertainty (u_random None: not usable)."""
        if quantity not in QUANTITIES:
            raise VerdictError(f"quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
        value = getattr(result, quantity)
        t_start, t_stop = result.window.get("t_start"), result.window.get("t_stop")
        swings = None
        if result.omega_n and t_start is not None and t_stop is not None:
            swings = float(result.omega_n) * (float(t_stop) - float(t_start)) / (2 * math.pi)
        budget = result.uncertainty_budget.get(quantity)
        if value is None or budget is None:
            return cls(None if value is None else float(value), None, 0.0, result.flags, swings)
        return cls(float(value), float(budget.u_random), float(budget.u_systematic), result.flags, swings,
                   float(budget.coverage_factor))

    @property
    def u_combined(self) -> float | None:
        if self.u_random is None:
            return None
        return math.hypot(self.u_random, self.u_systematic)


@dataclass(frozen=True)
class Decision:
    """A verdict with everything it was decided from (kg·m²).

    value: the measurand (None when unknown). u_c: combined standard uncertainty;
    U = k·u_c. deviation: value − nominal. zone: "conformance" (proven in),
    "nonconformance" (proven out), "uncertainty" (neither proven) or None.
    reasons: why INVALID / NOK, in words.
    """

    verdict: str
    value: float | None
    u_c: float | None
    U: float | None
    deviation: float | None
    zone: str | None
    rule: str
    reasons: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "value": self.value, "u_c": self.u_c, "U": self.U,
                "deviation": self.deviation, "zone": self.zone, "rule": self.rule, "reasons": list(self.reasons)}


def decide(value: float, u_c: float, spec: Specification, k: float | None = None,
           rules: QualityRules | None = None) -> Decision:
    """The conformity decision for a trustworthy value with its combined standard uncertainty.

    k: the coverage factor (None: the specification's; never below it). rules: their
    ``max_uncertainty_ratio`` makes a result with too large a U INVALID.
    """
    U = max(spec.coverage_factor, k or 0.0) * u_c
    cap = None if rules is None else rules.max_uncertainty_ratio
    half = (spec.upper - spec.lower) / 2
    if cap is not None and cap * half < U:
        return Decision(INVALID, value, u_c, U, value - spec.nominal, None, spec.rule,
                        (f"expanded uncertainty U = {U:.2g} kg·m² exceeds {cap:g} of the half-tolerance "
                         f"{half:.2g} kg·m² (test uncertainty ratio {half / U:.1f}, the recipe asks for at least "
                         f"{1 / cap:.1f})",))
    if spec.lower + U <= value <= spec.upper - U:
        zone = "conformance"
    elif value < spec.lower - U or value > spec.upper + U:
        zone = "nonconformance"
    else:
        zone = "uncertainty"
    inside = spec.lower <= value <= spec.upper
    reasons: list[str] = []
    if spec.rule == "simple":
        verdict = OK if inside else NOK
        if not inside:
            reasons.append(_outside(value, spec))
    elif zone == "conformance":
        verdict = OK
    elif zone == "nonconformance":
        verdict = NOK
        reasons.append(_outside(value, spec))
    else:
        verdict = spec.uncertain
        reasons.append(f"conformance not proven: {value:.7g} kg·m² with U = {U:.2g} kg·m² reaches beyond "
                       f"[{spec.lower:.7g}, {spec.upper:.7g}] kg·m² (guard band, ISO 14253-1)")
    return Decision(verdict, value, u_c, U, value - spec.nominal, zone, spec.rule, tuple(reasons))


def _outside(value: float, spec: Specification) -> str:
    side = "below the lower limit" if value < spec.lower else "above the upper limit"
    limit = spec.lower if value < spec.lower else spec.upper
    return f"{value:.7g} kg·m² {side} {limit:.7g} kg·m²"


def invalid_reasons(reading: Reading, rules: QualityRules) -> list[str]:
    """Why a reading cannot be trusted (empty: it can)."""
    reasons = [f"flag {f}" for f in reading.flags if f in rules.invalid_flags]
    if reading.value is None or reading.u_random is None:
        reasons.append("no value: the rig gives no J (stiffness or mass·com_distance missing), or no tare / "
                       "[object] for J_object / J_object_axis")
        return reasons
    if rules.max_std is not None and reading.u_random > rules.max_std:
        reasons.append(f"standard uncertainty {reading.u_random:.2g} kg·m² above the limit {rules.max_std:.2g} kg·m²")
    if rules.max_std_relative is not None and reading.value != 0 \
            and reading.u_random / abs(reading.value) > rules.max_std_relative:
        reasons.append(f"relative standard uncertainty {reading.u_random / abs(reading.value):.2g} above the limit "
                       f"{rules.max_std_relative:.2g}")
    if reading.swings is not None and reading.swings < rules.min_swings:
        reasons.append(f"{reading.swings:.1f} swings, fewer than {rules.min_swings:g}")
    return reasons


def judge_release(reading: Reading, spec: Specification, rules: QualityRules) -> Decision:
    """The verdict of one release on its own."""
    bad = invalid_reasons(reading, rules)
    if bad:
        return Decision(INVALID, reading.value, reading.u_combined, None,
                        None if reading.value is None else reading.value - spec.nominal, None, spec.rule, tuple(bad))
    assert reading.value is not None and reading.u_combined is not None
    return decide(reading.value, reading.u_combined, spec, reading.coverage_factor, rules)


@dataclass(frozen=True)
class PartResult:
    """The part's result from its releases (kg·m²).

    values: every release's value (None without one). used: indices (0-based)
    of the releases combined. excluded: {index, reason} for each release left out. mean, std (sample, ddof 1; None for one release),
    u_typeA = std/√n, u_fit = √(Σu_i²)/n, u_systematic, and the decision (its
    u_c and U). z: the agreement statistic per used release (None below 3).
    """

    releases: int
    values: tuple[float | None, ...]
    used: tuple[int, ...]
    excluded: tuple[dict[str, Any], ...]
    mean: float | None
    std: float | None
    u_typeA: float | None
    u_fit: float | None
    u_systematic: float | None
    z: tuple[float | None, ...]
    decision: Decision
    #: the joint identification the value came from (its ω_n, consistency test); None: the weighted mean
    joint: dict[str, Any] | None = None
    #: the part's budget: its random line (Type A repeatability or the releases' own, with its degrees of
    #: freedom), its systematic line, u_c, ν_eff (Welch–Satterthwaite), k and U
    uncertainty: dict[str, Any] | None = None

    @property
    def verdict(self) -> str:
        return self.decision.verdict

    def to_dict(self) -> dict[str, Any]:
        return {"releases": self.releases, "values": list(self.values), "used": list(self.used), "excluded": [dict(e) for e in self.excluded],
                "mean": self.mean, "std": self.std, "u_typeA": self.u_typeA, "u_fit": self.u_fit,
                "u_systematic": self.u_systematic, "z": list(self.z), "joint": self.joint,
                "uncertainty": self.uncertainty, **self.decision.to_dict()}


def agreement(values: Sequence[float], u: Sequence[float]) -> list[float]:
    """z_i of each value against the mean of the others (see the module docstring); n >= 2."""
    n = len(values)
    out = []
    for i in range(n):
        others = [j for j in range(n) if j != i]
        m = sum(values[j] for j in others) / (n - 1)
        u_m = math.sqrt(sum(u[j] ** 2 for j in others)) / (n - 1)
        den = math.hypot(u[i], u_m)
        out.append((values[i] - m) / den if den > 0 else (0.0 if values[i] == m else math.inf))
    return out


#: the joint value of the usable releases (their indices) as (value, random 1σ, consistency facts), kg·m²;
#: None when it cannot be had (the verdict then rests on the weighted mean)
JointOf = Callable[[Sequence[int]], "tuple[float, float, dict[str, Any]] | None"]


def _screen(readings: Sequence[Reading], rules: QualityRules) -> tuple[list[int], list[dict[str, Any]], list[str]]:
    """(the usable releases, the excluded ones with why, why the part cannot be judged): the invalid releases
    out, then the one that disagrees most with the others when at least 3 are left (the rule is in the
    module docstring)."""
    excluded: list[dict[str, Any]] = []
    usable: list[int] = []
    for i, r in enumerate(readings):
        bad = invalid_reasons(r, rules)
        if bad:
            excluded.append({"index": i, "reason": "invalid: " + "; ".join(bad)})
        else:
            usable.append(i)
    part_reasons: list[str] = []
    if len(usable) >= 2:
        zs = agreement([float(readings[i].value) for i in usable],  # type: ignore[arg-type]
                       [float(readings[i].u_random) for i in usable])  # type: ignore[arg-type]
        worst = max(range(len(zs)), key=lambda k: abs(zs[k]))
        if abs(zs[worst]) > rules.consistency_limit:
            if len(usable) >= 3:
                excluded.append({"index": usable[worst], "reason": f"disagrees with the other releases: "
                                 f"z = {zs[worst]:+.2f}, limit ±{rules.consistency_limit:g}"})
                usable.pop(worst)
                if max(abs(v) for v in _agreement_of(readings, usable)) > rules.consistency_limit:
                    part_reasons.append(f"releases disagree beyond ±{rules.consistency_limit:g} even after "
                                        "excluding the worst one")
            else:
                part_reasons.append(f"the 2 releases disagree: z = {abs(zs[worst]):.2f} > {rules.consistency_limit:g}")
    excluded.sort(key=lambda e: e["index"])
    n = len(readings)
    if len(usable) < max(1, rules.min_valid_releases):
        part_reasons.append(f"{len(usable)} usable of {n} releases, fewer than {max(1, rules.min_valid_releases)}")
        part_reasons += [f"release {e['index'] + 1}: {e['reason']}" for e in excluded]
    return usable, excluded, part_reasons


def _agreement_of(readings: Sequence[Reading], used: Sequence[int]) -> list[float]:
    return agreement([float(readings[i].value) for i in used],  # type: ignore[arg-type]
                     [float(readings[i].u_random) for i in used])  # type: ignore[arg-type]


def _value(vals: list[float], us: list[float], joint: tuple[float, float, dict[str, Any]] | None
           ) -> tuple[float, float, dict[str, Any] | None]:
    """(the part's value, its random 1σ from the releases' own uncertainties, the joint facts): the joint
    identification's where there is one, else the releases' mean weighed by their own uncertainty."""
    if joint is not None:
        return joint
    m = len(vals)
    if all(u > 0 for u in us):
        # each release weighed by its own uncertainty: a release whose model does not hold across
        # its record (a larger model-form term) counts for less
        w = [1.0 / u**2 for u in us]
        return sum(wi * v for wi, v in zip(w, vals)) / sum(w), 1.0 / math.sqrt(sum(w)), None
    return sum(vals) / m, math.sqrt(sum(u**2 for u in us)) / m, None


def _budget(m: int, u_a: float | None, u_fit: float, u_sys: float, k: float,
            spec: Specification) -> tuple[float, float, dict[str, Any]]:
    """(u_c, k, the part's budget): the larger random estimate with the systematic part once; a Type A term
    that sets it brings its m − 1 degrees of freedom into k (Welch–Satterthwaite)."""
    u_c = math.hypot(max(u_a or 0.0, u_fit), u_sys)
    type_a = u_a is not None and u_a > u_fit
    dof = welch_satterthwaite(u_c, [(u_a, m - 1)]) if type_a and u_a is not None else math.inf
    if type_a:
        # the repeatability (Type A, m − 1 degrees of freedom) sets the random part: few releases, a larger k
        k = max(k, _coverage_factor(dof, spec.coverage_factor))
    random_line = ({"source": f"repeatability of {m} releases (Type A, s/√n)", "u": u_a, "dof": m - 1}
                   if type_a else {"source": "the releases' own uncertainty (fit, model form; joint or weighted "
                                             "mean)", "u": u_fit, "dof": None})
    budget = {"lines": [random_line, {"source": "systematic, common to the releases (calibration, rig constants, "
                                                "clock, sensor scale)", "u": u_sys, "dof": None}],
              "u_c": u_c, "dof": dof if math.isfinite(dof) else None, "coverage_factor": k, "U": k * u_c}
    return u_c, k, budget


def combine(readings: Sequence[Reading], spec: Specification, rules: QualityRules,
            joint_of: JointOf | None = None) -> PartResult:
    """The part verdict from its releases (the rule is in the module docstring).

    joint_of: the releases identified jointly (shared physics, per-release
    nuisance: ``measurement.joint``); given, the part's value and its random
    uncertainty are the joint ones, the Type A floor still applies.
    """
    n = len(readings)
    if n == 0:
        raise VerdictError("a part needs at least one release")
    values = tuple(r.value for r in readings)
    usable, excluded, part_reasons = _screen(readings, rules)
    z: list[float | None] = [float(v) for v in _agreement_of(readings, usable)] if len(usable) >= 3 \
        else [None] * len(usable)
    if not usable:
        dec = Decision(INVALID, None, None, None, None, None, spec.rule, tuple(part_reasons))
        return PartResult(n, values, (), tuple(excluded), None, None, None, None, None, tuple(z), dec)
    vals = [float(readings[i].value) for i in usable]  # type: ignore[arg-type]
    us = [float(readings[i].u_random) for i in usable]  # type: ignore[arg-type]
    m = len(vals)
    mean, u_fit, joint_facts = _value(vals, us, joint_of(tuple(usable)) if joint_of is not None and m >= 2 else None)
    std = math.sqrt(sum((v - mean) ** 2 for v in vals) / (m - 1)) if m > 1 else None
    u_a = std / math.sqrt(m) if std is not None else None
    u_sys = max(readings[i].u_systematic for i in usable)
    # a joint value's u is its own (Birge-scaled where the releases scatter): a release's k may rest on a line that
    # u does not hold (the rig's reproducibility between releases, with its few degrees of freedom)
    k = max([spec.coverage_factor] + ([readings[i].coverage_factor or 0.0 for i in usable] if joint_facts is None
                                      else []))
    u_c, k, budget = _budget(m, u_a, u_fit, u_sys, k, spec)
    if part_reasons:
        dec = Decision(INVALID, mean, u_c, k * u_c, mean - spec.nominal, None, spec.rule, tuple(part_reasons))
    else:
        dec = decide(mean, u_c, spec, k, rules)
    return PartResult(n, values, tuple(usable), tuple(excluded), mean, std, u_a, u_fit, u_sys, tuple(z), dec,
                      joint_facts, budget)
