"""Gauge studies: does the instrument measure well enough to accept or reject parts?

Pure and hardware-free; every figure in the unit of the values (SI inside: kg·m² for J).

**Type 1 study** (VDA 5 "Capability of Measurement Processes"; Robert Bosch GmbH, "Booklet 10:
Capability of Measurement and Test Processes"; the bias study of AIAG "Measurement Systems Analysis",
4th edition, ch. III-B): one reference part of known value x_ref measured n times (n ≥ 25, 50
recommended) by one instrument and one appraiser; tolerance T of the characteristic:

    Cg  = (K·T) / (L·s)                 K = 0.2 (20 % of T), L = 6 (6s)
    Cgk = (K/2·T − |x̄ − x_ref|) / (L/2·s)

both against 1.33. The bias x̄ − x_ref is tested with Student's t, t = bias / (s/√n) with n − 1
degrees of freedom (two-sided), with its confidence interval bias ± t_{1−α/2}·s/√n. Solved for T, the
smallest tolerance this instrument can accept parts of: T_min = 1.33·L·s/K at Cg = 1.33, and
(1.33·L/2·s + |bias|)/(K/2) at Cgk = 1.33. The run chart: the values in their order, x_ref and
x_ref ± K/2·T.

**Gauge R&R, ANOVA method** (AIAG MSA 4th edition, ch. III-B "Analysis of Variance (ANOVA) Method"):
p parts × a appraisers × r trials, balanced (every part measured r times by every appraiser). The
two-way random-effects ANOVA with interaction; appraiser and part are tested against the interaction's
mean square, the interaction against repeatability. When the interaction is not significant
(p > ``POOL_ALPHA`` = 0.25) it is pooled into repeatability, MS_pool = (SS_AP + SS_E)/(df_AP + df_E),
and the appraiser and part are tested against MS_pool. Variance components (negative estimates set to 0):

    EV² = MS_E (or MS_pool)        INT² = (MS_AP − MS_E)/r (0 when pooled)
    AV² = (MS_A − MS_AP)/(p·r)     PV²  = (MS_P − MS_AP)/(a·r)      (MS_pool for MS_AP when pooled)
    GRR² = EV² + AV² + INT²        TV²  = GRR² + PV²

EV, AV, INT, GRR, PV, TV are standard deviations (1σ). %GRR of the process = 100·GRR/TV; %GRR of the
tolerance = 100·L·GRR/T with L = 6 (AIAG 4th edition: 6σ covers 99.73 %; the 3rd edition used 5.15σ,
99 %: pass ``spread=5.15``); ndc = ⌊1.41·PV/GRR⌋. Bands: below 10 % acceptable, 10 to 30 %
conditionally acceptable (the application, the cost of the gauge decide), above 30 % not acceptable;
ndc ≥ 5 wanted.

Unbalanced studies (a missing or an extra trial, a part one appraiser did not measure) are refused: the
ANOVA sums of squares above are the balanced design's; dropping the incomplete part or trial is the
quality engineer's decision, not this module's.

**Capability with the gauge's figures** (``capability_warnings``): a process's Cp, Cpk (and Pp, Ppk)
see the process's scatter and the gauge's together (σ²_observed = σ²_process + GRR²); when the gauge's
%GRR is above 30 %, its ndc below 5, or its Cg or Cgk below 1.33 at the specification's tolerance,
those indices say more about the gauge than about the process (AIAG MSA 4th ed., ch. I; VDA 5). A Gauge
R&R below the manual's design (``grr_design``) gives indicative warnings; one whose parts do not span the
process gives none of %GRR of the process nor of ndc: its %GRR of the tolerance is the gauge's figure.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import Any, Hashable, Iterable, Mapping, Sequence

import numpy as np

from .errors import InvalidInput

#: Cg, Cgk at or above this accept the instrument (VDA 5, Bosch booklet 10)
CG_LIMIT = 1.33
#: share of the tolerance the Type 1 study's 6s must fit in (K), and the spread (L) in s
TOLERANCE_SHARE = 0.2
CG_SPREAD = 6.0
#: fewest measurements of a Type 1 study, and the recommended count
TYPE1_MIN = 25
TYPE1_RECOMMENDED = 50
#: the interaction of a Gauge R&R is pooled into repeatability when its p-value is above this
POOL_ALPHA = 0.25
#: σ multiple of a study variation against the tolerance (AIAG MSA 4th edition); the 3rd used 5.15
GRR_SPREAD = 6.0
#: %GRR bands and the fewest distinct categories (AIAG MSA 4th edition)
GRR_ACCEPTABLE, GRR_CONDITIONAL = 10.0, 30.0
NDC_MIN = 5
ACCEPTABLE, CONDITIONAL, NOT_ACCEPTABLE = "acceptable", "conditional", "not acceptable"


class GaugeStudyError(InvalidInput):
    """A gauge study that cannot be evaluated: too few measurements, an unbalanced design, no scatter."""


def _finite(values: Iterable[Any], what: str) -> list[float]:
    out = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
            raise GaugeStudyError(f"{what} must be finite numbers, got {v!r}")
        out.append(float(v))
    return out


def _positive(value: float | None, what: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not math.isfinite(value) or value <= 0:
        raise GaugeStudyError(f"{what} must be a positive number, got {value!r}")
    return float(value)


def grr_verdict(percent: float) -> str:
    """The AIAG band of a %GRR: "acceptable" below 10 %, "conditional" 10 to 30 %, "not acceptable" above."""
    if percent < GRR_ACCEPTABLE:
        return ACCEPTABLE
    return CONDITIONAL if percent <= GRR_CONDITIONAL else NOT_ACCEPTABLE


# ---------------------------------------------------------------------------------------------------------
# Type 1 study


@dataclass(frozen=True)
class BiasTest:
    """The bias of repeated measurements of a reference against zero (two-sided Student's t).

    bias = mean − reference; s: sample standard deviation (n − 1); se = s/√n; t = bias/se with dof = n − 1;
    p: two-sided p-value; ci: the ``level`` confidence interval of the bias.
    """

    n: int
    mean: float
    reference: float
    bias: float
    s: float
    se: float
    t: float
    dof: int
    p: float
    level: float
    ci: tuple[float, float]

    @property
    def significant(self) -> bool:
        """The bias differs from zero at 1 − ``level`` (the interval does not hold 0)."""
        return self.p < 1.0 - self.level

    def to_dict(self) -> dict[str, Any]:
        return {"n": self.n, "mean": self.mean, "reference": self.reference, "bias": self.bias, "s": self.s,
                "se": self.se, "t": self.t, "dof": self.dof, "p": self.p, "level": self.level, "ci": list(self.ci),
                "significant": self.significant}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> BiasTest:
        lo, hi = d["ci"]
        return cls(int(d["n"]), float(d["mean"]), float(d["reference"]), float(d["bias"]), float(d["s"]),
                   float(d["se"]), float(d["t"]), int(d["dof"]), float(d["p"]), float(d["level"]), (float(lo), float(hi)))


def bias_test(values: Sequence[float], reference: float, level: float = 0.95) -> BiasTest:
    """The bias of ``values`` (at least 2, not all equal) from ``reference``, with its t-test."""
    from scipy.stats import t as student

    x = np.asarray(_finite(values, "measurements of the reference"))
    ref = _finite([reference], "the reference value")[0]
    if not 0.0 < level < 1.0:
        raise GaugeStudyError(f"the confidence level must lie between 0 and 1, got {level!r}")
    if x.size < 2:
        raise GaugeStudyError(f"a bias test needs at least 2 measurements, got {x.size}")
    s = float(np.std(x, ddof=1))
    if not s > 0:
        raise GaugeStudyError(f"all {x.size} measurements read {x[0]!r}: no scatter to test the bias against "
                              "(the instrument's resolution is too coarse for this study)")
    mean = float(np.mean(x))
    dof = int(x.size - 1)
    se = s / math.sqrt(x.size)
    bias = mean - ref
    t = bias / se
    half = float(student.ppf(0.5 + level / 2, dof)) * se
    return BiasTest(int(x.size), mean, ref, bias, s, se, t, dof, float(2 * student.sf(abs(t), dof)), level,
                    (bias - half, bias + half))


@dataclass(frozen=True)
class Type1Study:
    """A Type 1 study's figures (see the module docstring), in the unit of the values.

    values: the measurements in their order (the run chart); chart_lower, chart_upper: x_ref ∓ K/2·T;
    cg, cgk and the tolerances at which they reach 1.33 (min_tolerance_cg, min_tolerance_cgk);
    resolution and its share of T in % (None when not given); notes: what a reader should know
    (fewer than 50 values, a coarse resolution, a significant bias).
    """

    values: tuple[float, ...]
    reference: float
    tolerance: float
    bias: BiasTest
    cg: float
    cgk: float
    min_tolerance_cg: float
    min_tolerance_cgk: float
    chart_lower: float
    chart_upper: float
    resolution: float | None
    resolution_percent: float | None
    notes: tuple[str, ...]

    @property
    def n(self) -> int:
        return len(self.values)

    @property
    def s(self) -> float:
        return self.bias.s

    @property
    def capable(self) -> bool:
        return self.cg >= CG_LIMIT and self.cgk >= CG_LIMIT

    def cg_at(self, tolerance: float) -> float:
        """Cg of this instrument against another tolerance."""
        return TOLERANCE_SHARE * tolerance / (CG_SPREAD * self.s)

    def cgk_at(self, tolerance: float) -> float:
        """Cgk of this instrument against another tolerance."""
        return (TOLERANCE_SHARE / 2 * tolerance - abs(self.bias.bias)) / (CG_SPREAD / 2 * self.s)

    def to_dict(self) -> dict[str, Any]:
        return {"values": list(self.values), "reference": self.reference, "tolerance": self.tolerance,
                "bias": self.bias.to_dict(), "cg": self.cg, "cgk": self.cgk, "capable": self.capable,
                "min_tolerance_cg": self.min_tolerance_cg, "min_tolerance_cgk": self.min_tolerance_cgk,
                "chart_lower": self.chart_lower, "chart_upper": self.chart_upper, "resolution": self.resolution,
                "resolution_percent": self.resolution_percent, "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Type1Study:
        def opt(v: Any) -> float | None:
            return None if v is None else float(v)
        return cls(tuple(float(v) for v in d["values"]), float(d["reference"]), float(d["tolerance"]),
                   BiasTest.from_dict(d["bias"]), float(d["cg"]), float(d["cgk"]), float(d["min_tolerance_cg"]),
                   float(d["min_tolerance_cgk"]), float(d["chart_lower"]), float(d["chart_upper"]),
                   opt(d.get("resolution")), opt(d.get("resolution_percent")), tuple(d.get("notes", ())))


def type1_study(values: Sequence[float], reference: float, tolerance: float, *, resolution: float | None = None,
                level: float = 0.95) -> Type1Study:
    """The Type 1 study of ``values``: measurements of one reference part of known value ``reference``
    (at least ``TYPE1_MIN``), against the characteristic's ``tolerance`` (USL − LSL, > 0).

    resolution: the instrument's smallest step, if known (VDA 5 wants it ≤ 5 % of T).
    """
    x = _finite(values, "measurements of the reference")
    if len(x) < TYPE1_MIN:
        raise GaugeStudyError(f"a Type 1 study needs at least {TYPE1_MIN} measurements of the reference part "
                              f"({TYPE1_RECOMMENDED} recommended), got {len(x)}")
    T = _positive(tolerance, "the tolerance (USL − LSL)")
    res = _positive(resolution, "the resolution")
    assert T is not None
    b = bias_test(x, reference, level)
    half = TOLERANCE_SHARE / 2 * T
    cg = TOLERANCE_SHARE * T / (CG_SPREAD * b.s)
    cgk = (half - abs(b.bias)) / (CG_SPREAD / 2 * b.s)
    res_pct = None if res is None else 100.0 * res / T
    notes = []
    if len(x) < TYPE1_RECOMMENDED:
        notes.append(f"{len(x)} measurements: {TYPE1_RECOMMENDED} are recommended for a Type 1 study")
    if res_pct is not None and res_pct > 5.0:
        notes.append(f"the resolution is {res_pct:.3g} % of the tolerance: at most 5 % is wanted")
    if b.significant:
        notes.append(f"the bias differs from zero (p = {b.p:.3g}): correct the instrument's offset or its reference")
    return Type1Study(tuple(x), b.reference, T, b, cg, cgk, CG_LIMIT * CG_SPREAD * b.s / TOLERANCE_SHARE,
                      (CG_LIMIT * CG_SPREAD / 2 * b.s + abs(b.bias)) / (TOLERANCE_SHARE / 2),
                      b.reference - half, b.reference + half, res, res_pct, tuple(notes))


# ---------------------------------------------------------------------------------------------------------
# Gauge R&R, ANOVA method


@dataclass(frozen=True)
class AnovaRow:
    """One line of an ANOVA table; f and p are None on the error line and the total."""

    source: str
    df: int
    ss: float
    ms: float | None
    f: float | None
    p: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "df": self.df, "ss": self.ss, "ms": self.ms, "f": _json_float(self.f),
                "p": self.p}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> AnovaRow:
        def opt(v: Any) -> float | None:
            return None if v is None else float(v)
        f = d.get("f")
        return cls(str(d["source"]), int(d["df"]), float(d["ss"]), opt(d.get("ms")),
                   math.inf if f == "inf" else opt(f), opt(d.get("p")))


def _json_float(v: float | None) -> float | str | None:
    return "inf" if v is not None and math.isinf(v) else v


#: the sources of a Gauge R&R's ANOVA table
APPRAISER, PART, INTERACTION, REPEATABILITY, TOTAL = "appraiser", "part", "appraiser × part", "repeatability", "total"


@dataclass(frozen=True)
class GaugeRR:
    """A Gauge R&R (ANOVA method) and its figures (see the module docstring).

    values[part][appraiser][trial]; parts, appraisers: their labels. anova: the table with the interaction
    (appraiser, part, interaction, repeatability, total); pooled: the interaction's p-value was above
    ``POOL_ALPHA`` and ``anova_pooled`` (appraiser, part, repeatability, total) is the table the components
    rest on. ev, av, interaction, grr, pv, tv: standard deviations (1σ). tolerance: USL − LSL (None: not
    given; the %-of-tolerance figures are then None). spread: the σ multiple against the tolerance.
    """

    values: tuple[tuple[tuple[float, ...], ...], ...]
    parts: tuple[str, ...]
    appraisers: tuple[str, ...]
    anova: tuple[AnovaRow, ...]
    pooled: bool
    anova_pooled: tuple[AnovaRow, ...] | None
    ev: float
    av: float
    interaction: float
    grr: float
    pv: float
    tv: float
    tolerance: float | None
    spread: float = GRR_SPREAD

    @property
    def trials(self) -> int:
        return len(self.values[0][0])

    @property
    def pct_grr_process(self) -> float:
        """%GRR of the total variation TV (100·GRR/TV)."""
        return 100.0 * self.grr / self.tv if self.tv > 0 else 0.0

    def pct_of_process(self, sigma: float) -> float:
        """A component (EV, AV, INT, GRR, PV) in % of TV."""
        return 100.0 * sigma / self.tv if self.tv > 0 else 0.0

    def pct_of_tolerance(self, sigma: float, tolerance: float | None = None) -> float | None:
        """A component's spread·σ in % of ``tolerance`` (default: the study's); None without one."""
        T = self.tolerance if tolerance is None else tolerance
        return None if T is None else 100.0 * self.spread * sigma / T

    @property
    def pct_grr_tolerance(self) -> float | None:
        return self.pct_of_tolerance(self.grr)

    @property
    def ndc(self) -> int | None:
        """Number of distinct categories ⌊1.41·PV/GRR⌋ (None when GRR is 0)."""
        return int(math.floor(1.41 * self.pv / self.grr)) if self.grr > 0 else None

    @property
    def verdict_process(self) -> str:
        return grr_verdict(self.pct_grr_process)

    @property
    def verdict_tolerance(self) -> str | None:
        pct = self.pct_grr_tolerance
        return None if pct is None else grr_verdict(pct)

    def to_dict(self) -> dict[str, Any]:
        return {"values": [[list(c) for c in p] for p in self.values], "parts": list(self.parts),
                "appraisers": list(self.appraisers), "trials": self.trials,
                "anova": [r.to_dict() for r in self.anova], "pooled": self.pooled,
                "anova_pooled": None if self.anova_pooled is None else [r.to_dict() for r in self.anova_pooled],
                "ev": self.ev, "av": self.av, "interaction": self.interaction, "grr": self.grr, "pv": self.pv,
                "tv": self.tv, "tolerance": self.tolerance, "spread": self.spread,
                "pct_grr_process": self.pct_grr_process, "pct_grr_tolerance": self.pct_grr_tolerance,
                "ndc": self.ndc, "verdict_process": self.verdict_process, "verdict_tolerance": self.verdict_tolerance}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GaugeRR:
        pooled_rows = d.get("anova_pooled")
        return cls(tuple(tuple(tuple(float(v) for v in c) for c in p) for p in d["values"]),
                   tuple(str(p) for p in d["parts"]), tuple(str(a) for a in d["appraisers"]),
                   tuple(AnovaRow.from_dict(r) for r in d["anova"]), bool(d["pooled"]),
                   None if pooled_rows is None else tuple(AnovaRow.from_dict(r) for r in pooled_rows),
                   float(d["ev"]), float(d["av"]), float(d["interaction"]), float(d["grr"]), float(d["pv"]),
                   float(d["tv"]), None if d.get("tolerance") is None else float(d["tolerance"]),
                   float(d.get("spread", GRR_SPREAD)))


def _balanced(values: Sequence[Sequence[Sequence[float]]]) -> np.ndarray:
    """values[part][appraiser][trial] as a p × a × r array; GaugeStudyError when unbalanced or too small."""
    p = len(values)
    if p < 2:
        raise GaugeStudyError(f"a Gauge R&R needs at least 2 parts, got {p}")
    a_counts = {len(part) for part in values}
    if len(a_counts) != 1:
        raise GaugeStudyError(f"unbalanced study: the parts were measured by different numbers of appraisers "
                              f"({sorted(a_counts)}); every appraiser must measure every part")
    r_counts = {f"part {i + 1} appraiser {j + 1}": len(cell) for i, part in enumerate(values) for j, cell in enumerate(part)}
    _same_trials(r_counts)
    a, r = a_counts.pop(), next(iter(r_counts.values()))
    if a < 2:
        raise GaugeStudyError(f"a Gauge R&R needs at least 2 appraisers, got {a} (one instrument and one "
                              "appraiser: a Type 1 study)")
    if r < 2:
        raise GaugeStudyError(f"a Gauge R&R needs at least 2 trials per part and appraiser, got {r}")
    flat = _finite((v for part in values for cell in part for v in cell), "the study's measurements")
    return np.asarray(flat, dtype=float).reshape(p, a, r)


def _same_trials(counts: Mapping[str, int]) -> None:
    """GaugeStudyError naming the cells whose number of trials differs from the usual one."""
    if len(set(counts.values())) <= 1:
        return
    usual = Counter(counts.values()).most_common(1)[0][0]
    odd = [f"{cell}: {n}" for cell, n in counts.items() if n != usual]
    raise GaugeStudyError(f"unbalanced study: every part needs the same number of trials by every appraiser; "
                          f"{usual} in most cells, but " + ", ".join(odd[:10]) + (" …" if len(odd) > 10 else ""))


def _anova(x: np.ndarray) -> dict[str, tuple[int, float]]:
    """The two-way crossed ANOVA's (df, SS) of a p × a × r array, by the balanced design's sums."""
    p, a, r = x.shape
    grand = x.mean()
    part_means = x.mean(axis=(1, 2))
    appr_means = x.mean(axis=(0, 2))
    cell_means = x.mean(axis=2)
    ss_part = a * r * float(np.sum((part_means - grand) ** 2))
    ss_appr = p * r * float(np.sum((appr_means - grand) ** 2))
    ss_cells = r * float(np.sum((cell_means - grand) ** 2))
    ss_error = float(np.sum((x - cell_means[:, :, None]) ** 2))
    return {PART: (p - 1, ss_part), APPRAISER: (a - 1, ss_appr),
            INTERACTION: ((p - 1) * (a - 1), max(0.0, ss_cells - ss_part - ss_appr)),
            REPEATABILITY: (p * a * (r - 1), ss_error), TOTAL: (p * a * r - 1, float(np.sum((x - grand) ** 2)))}


def _row(source: str, df: int, ss: float, against: float | None, dfd: int) -> AnovaRow:
    """An ANOVA line tested against the mean square ``against`` with ``dfd`` degrees of freedom."""
    from scipy.stats import f as fisher

    ms = ss / df
    if against is None:
        return AnovaRow(source, df, ss, ms, None, None)
    f = ms / against if against > 0 else math.inf
    return AnovaRow(source, df, ss, ms, f, 0.0 if math.isinf(f) else float(fisher.sf(f, df, dfd)))


def _tables(sums: dict[str, tuple[int, float]], pool_alpha: float) -> tuple[tuple[AnovaRow, ...], tuple[AnovaRow, ...] | None]:
    """The full table and, when the interaction is pooled, the reduced one."""
    (df_a, ss_a), (df_p, ss_p), (df_i, ss_i), (df_e, ss_e), (df_t, ss_t) = (
        sums[k] for k in (APPRAISER, PART, INTERACTION, REPEATABILITY, TOTAL))
    ms_i, ms_e = ss_i / df_i, ss_e / df_e
    interaction = _row(INTERACTION, df_i, ss_i, ms_e, df_e)
    full = (_row(APPRAISER, df_a, ss_a, ms_i, df_i), _row(PART, df_p, ss_p, ms_i, df_i), interaction,
            _row(REPEATABILITY, df_e, ss_e, None, 0), AnovaRow(TOTAL, df_t, ss_t, None, None, None))
    if interaction.p is None or interaction.p <= pool_alpha:
        return full, None
    df_pool, ss_pool = df_i + df_e, ss_i + ss_e
    ms_pool = ss_pool / df_pool
    reduced = (_row(APPRAISER, df_a, ss_a, ms_pool, df_pool), _row(PART, df_p, ss_p, ms_pool, df_pool),
               _row(REPEATABILITY, df_pool, ss_pool, None, 0), AnovaRow(TOTAL, df_t, ss_t, None, None, None))
    return full, reduced


def gauge_rr(values: Sequence[Sequence[Sequence[float]]], *, tolerance: float | None = None,
             parts: Sequence[Hashable] | None = None, appraisers: Sequence[Hashable] | None = None,
             pool_alpha: float = POOL_ALPHA, spread: float = GRR_SPREAD) -> GaugeRR:
    """The Gauge R&R (ANOVA method) of ``values[part][appraiser][trial]`` (balanced: at least 2 parts,
    2 appraisers, 2 trials; every appraiser measures every part the same number of times).

    tolerance: USL − LSL for the %-of-tolerance figures; parts, appraisers: labels (default 1, 2, … and
    A, B, …); pool_alpha: the interaction is pooled when its p-value is above it (1 never pools); spread: the σ
    multiple against the tolerance (6, or 5.15 for the 3rd edition's figures).
    """
    x = _balanced(values)
    p, a, r = x.shape
    T = _positive(tolerance, "the tolerance (USL − LSL)")
    _positive(spread, "the spread (σ multiple)")
    part_labels = _labels(parts, p, [str(i + 1) for i in range(p)], "parts")
    appr_labels = _labels(appraisers, a, [_letter(j) for j in range(a)], "appraisers")
    sums = _anova(x)
    if not sums[REPEATABILITY][1] > 0:
        raise GaugeStudyError("every part read the same value in every trial: no repeatability to estimate "
                              "(the instrument's resolution is too coarse for this study)")
    full, reduced = _tables(sums, pool_alpha)
    rows = {row.source: row for row in (reduced or full)}
    ms_e = rows[REPEATABILITY].ms
    ms_i = ms_e if reduced is not None else rows[INTERACTION].ms
    assert ms_e is not None and ms_i is not None
    ms_a, ms_p = rows[APPRAISER].ms or 0.0, rows[PART].ms or 0.0
    ev2 = ms_e
    int2 = 0.0 if reduced is not None else max(0.0, (ms_i - ms_e) / r)
    av2 = max(0.0, (ms_a - ms_i) / (p * r))
    pv2 = max(0.0, (ms_p - ms_i) / (a * r))
    grr2 = ev2 + av2 + int2
    values_t = tuple(tuple(tuple(float(v) for v in cell) for cell in part) for part in x)
    return GaugeRR(values_t, part_labels, appr_labels, full, reduced is not None, reduced, math.sqrt(ev2),
                   math.sqrt(av2), math.sqrt(int2), math.sqrt(grr2), math.sqrt(pv2), math.sqrt(grr2 + pv2), T,
                   float(spread))


def _letter(j: int) -> str:
    return chr(ord("A") + j) if j < 26 else f"A{j + 1}"


def _labels(given: Sequence[Hashable] | None, n: int, default: list[str], what: str) -> tuple[str, ...]:
    if given is None:
        return tuple(default)
    labels = tuple(str(g) for g in given)
    if len(labels) != n or len(set(labels)) != n:
        raise GaugeStudyError(f"{n} distinct labels of the {what} expected, got {list(labels)}")
    return labels


def gauge_rr_records(records: Iterable[tuple[Hashable, Hashable, float]], **kwargs: Any) -> GaugeRR:
    """The Gauge R&R of records (part, appraiser, value), e.g. from the store: grouped by part and
    appraiser in the order first seen, trials in record order. Unbalanced groups are refused, naming the
    part and appraiser whose count differs. Keyword arguments as ``gauge_rr``."""
    cells: dict[Hashable, dict[Hashable, list[float]]] = {}
    appraisers: dict[Hashable, None] = {}
    for part, appraiser, value in records:
        cells.setdefault(part, {}).setdefault(appraiser, []).append(value)
        appraisers.setdefault(appraiser)
    missing = [f"part {p!s} by {a!s}" for p, by in cells.items() for a in appraisers if a not in by]
    if missing:
        raise GaugeStudyError("unbalanced study: every appraiser must measure every part; missing "
                              + ", ".join(missing[:10]) + (" …" if len(missing) > 10 else ""))
    _same_trials({f"part {p!s} by {a!s}": len(cells[p][a]) for p in cells for a in appraisers})
    values = [[cells[p][a] for a in appraisers] for p in cells]
    return gauge_rr(values, parts=list(cells), appraisers=list(appraisers), **kwargs)


# ---------------------------------------------------------------------------------------------------------
# capability with the gauge's figures


@dataclass(frozen=True)
class GaugeWarning:
    """A gauge figure that makes the capability indices meaningless: ``figure`` ("%GRR of the tolerance",
    "%GRR of the process", "ndc", "Cg", "Cgk"), its value, the limit it fails, and a sentence."""

    figure: str
    value: float
    limit: float
    message: str

    def to_dict(self) -> dict[str, Any]:
        return {"figure": self.figure, "value": self.value, "limit": self.limit, "message": self.message}


#: the capability indices the warnings are about
CAPABILITY_INDICES = "Cp, Cpk, Pp and Ppk"


def capability_warnings(*, grr: GaugeRR | None = None, type1: Type1Study | None = None,
                        tolerance: float | None = None) -> tuple[GaugeWarning, ...]:
    """Why a process's capability indices are not to be trusted with this gauge (empty: no objection).

    tolerance: the specification's USL − LSL the indices are computed against; the gauge's %GRR of the
    tolerance and its Cg, Cgk are evaluated at it (default: the tolerance each study was run with).
    """
    out: list[GaugeWarning] = []

    def warn(figure: str, value: float, limit: float, why: str) -> None:
        out.append(GaugeWarning(figure, value, limit, f"{CAPABILITY_INDICES} are not meaningful: {why}"))

    if grr is not None:
        # a small study's figures are indicative, and with parts all alike those against PV say nothing
        from .grr_design import below_design, design, parts_alike

        alike = parts_alike(grr)
        hedge = f" (indicative: {design(grr)}, below the AIAG MSA design)" if below_design(grr) else ""
        pct_t = grr.pct_of_tolerance(grr.grr, tolerance)
        if pct_t is not None and pct_t > GRR_CONDITIONAL:
            warn("%GRR of the tolerance", pct_t, GRR_CONDITIONAL,
                 f"the gauge's %GRR is {pct_t:.3g} % of the tolerance (above {GRR_CONDITIONAL:g} %){hedge}")
        if not alike and grr.pct_grr_process > GRR_CONDITIONAL:
            warn("%GRR of the process", grr.pct_grr_process, GRR_CONDITIONAL,
                 f"the gauge's %GRR is {grr.pct_grr_process:.3g} % of the process variation (above "
                 f"{GRR_CONDITIONAL:g} %){hedge}")
        ndc = grr.ndc
        if not alike and ndc is not None and ndc < NDC_MIN:
            n = "category" if ndc == 1 else "categories"
            warn("ndc", float(ndc), float(NDC_MIN),
                 f"the gauge tells only {ndc} distinct {n} of parts apart (at least {NDC_MIN} wanted){hedge}")
    if type1 is not None:
        T = type1.tolerance if tolerance is None else tolerance
        for figure, value in (("Cg", type1.cg_at(T)), ("Cgk", type1.cgk_at(T))):
            if value < CG_LIMIT:
                warn(figure, value, CG_LIMIT, f"the gauge's {figure} is {value:.3g} at this tolerance (below {CG_LIMIT:g})")
    return tuple(out)
