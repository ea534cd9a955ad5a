"""Statistical process control of a series of parts: control charts, capability, run rules.

Pure and hardware-free. Two Shewhart charts (D. C. Montgomery, "Introduction
to Statistical Quality Control", ch. 6; ISO 7870-2:2023 "Control charts —
Part 2: Shewhart control charts"):

* individuals / moving range (I-MR), one value per part:
  centre x̄, MR̄ = mean |x_i − x_{i−1}|, σ_within = MR̄/d2(2),
  limits x̄ ± 3σ_within; MR chart UCL = D4(2)·MR̄, LCL = 0.
* X̄–R, one subgroup per part (its n releases, 2 ≤ n ≤ 10):
  centre X̿ (mean of the subgroup means), R̄ (mean range),
  σ_within = R̄/d2(n), limits X̿ ± A2(n)·R̄ with A2 = 3/(d2·√n);
  R chart UCL = D4(n)·R̄, LCL = D3(n)·R̄, D3,4 = 1 ∓ 3·d3/d2 (D3 ≥ 0).

* X̄–S, one subgroup per part (its n releases, 2 ≤ n ≤ 25): centre X̿, S̄ (mean
  sample standard deviation), σ_within = S̄/c4(n), limits X̿ ± 3σ_within/√n;
  S chart UCL = B4(n)·S̄, LCL = B3(n)·S̄, B3,4 = 1 ∓ 3·√(1 − c4²)/c4 (B3 ≥ 0),
  c4(n) = √(2/(n − 1))·Γ(n/2)/Γ((n − 1)/2).

Capability against the specification limits LSL/USL:
Cp = (USL − LSL)/(6σ_within), Cpk = min(USL − x̄, x̄ − LSL)/(3σ_within);
the same with the overall sample σ (ddof 1) of the individual values gives
Pp and Ppk.

Run rules on the plotted points (the individuals, or the subgroup means),
with σ of a point = σ_within (I) or σ_within/√n (X̄), after Western Electric
("Statistical Quality Control Handbook", 1956) / Nelson (1984):

1. ``beyond_limits``: a point outside the control limits (±3σ);
2. ``run_of_8``: 8 points in a row on one side of the centre line;
3. ``trend_of_6``: 6 points in a row steadily increasing or decreasing;
4. ``2_of_3_beyond_2sigma``: 2 of 3 points in a row beyond 2σ on the same side.

Each violation is reported at the index of the point that completes it.

The confidence interval of Cp and Cpk (``capability_interval``): Cp from the χ²
distribution of the sample variance with ν = N − 1, Cpk by Bissell's normal
approximation, Cpk ± z·√(1/(9N) + Cpk²/(2(N − 1))) (Montgomery, ch. 8.3; N: the
values the σ rests on). Below ``SMALL_SAMPLE`` values they are too wide to
decide on, and are said to be.

The capability indices see the gauge's scatter with the process's; ``with_gauge`` attaches the gauge
studies' objections to them (``measurement.gauge.capability_warnings``: %GRR above 30 %, ndc below 5,
Cg or Cgk below 1.33 at the specification's tolerance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

from .errors import InvalidInput
from .gauge import GaugeRR, GaugeWarning, Type1Study, capability_warnings

#: control chart constants d2 and d3 for subgroup size n (Montgomery, Appendix Table VI)
D2 = {2: 1.128, 3: 1.693, 4: 2.059, 5: 2.326, 6: 2.534, 7: 2.704, 8: 2.847, 9: 2.970, 10: 3.078}
D3_SIGMA = {2: 0.853, 3: 0.888, 4: 0.880, 5: 0.864, 6: 0.848, 7: 0.833, 8: 0.820, 9: 0.808, 10: 0.797}

#: fewer values than this give a capability index too uncertain to decide on (Montgomery, ch. 8)
SMALL_SAMPLE = 25

RUN_LENGTH = 8
TREND_LENGTH = 6


class SpcError(InvalidInput):
    """Too few values, or a subgroup size without chart constants."""


def chart_constants(n: int) -> dict[str, float]:
    """A2, D3, D4 (and d2, d3) for subgroup size n (2 … 10)."""
    if n not in D2:
        raise SpcError(f"control chart constants exist for subgroups of 2 to 10 values, got {n}")
    d2, d3 = D2[n], D3_SIGMA[n]
    return {"d2": d2, "d3": d3, "A2": 3.0 / (d2 * math.sqrt(n)), "D3": max(0.0, 1.0 - 3.0 * d3 / d2),
            "D4": 1.0 + 3.0 * d3 / d2}


@dataclass(frozen=True)
class Violation:
    rule: str
    index: int  # 0-based index of the point that completes it

    def to_dict(self) -> dict[str, Any]:
        return {"rule": self.rule, "index": self.index}


@dataclass(frozen=True)
class SpcSummary:
    """A control chart's numbers (units of the values, e.g. kg·m²).

    chart: "I-MR" | "Xbar-R". points: the plotted values (individuals or
    subgroup means); ranges: moving ranges (len − 1) or subgroup ranges.
    subgroup: n of X̄–R (1 for I-MR). cp, cpk, pp, ppk: None without limits or σ = 0.
    gauge_warnings: why the gauge makes cp … ppk meaningless (``with_gauge``; empty: none known).
    """

    chart: str
    n_points: int
    subgroup: int
    points: tuple[float, ...]
    ranges: tuple[float, ...]
    mean: float
    sigma_within: float
    sigma_overall: float
    ucl: float
    lcl: float
    range_mean: float
    range_ucl: float
    range_lcl: float
    lsl: float | None
    usl: float | None
    cp: float | None
    cpk: float | None
    pp: float | None
    ppk: float | None
    outside: tuple[int, ...]
    violations: tuple[Violation, ...] = field(default=())
    gauge_warnings: tuple[GaugeWarning, ...] = field(default=())

    @property
    def in_control(self) -> bool:
        return not self.violations

    def to_dict(self, include_points: bool = False) -> dict[str, Any]:
        d = {"chart": self.chart, "n_points": self.n_points, "subgroup": self.subgroup, "mean": self.mean,
             "sigma_within": self.sigma_within, "sigma_overall": self.sigma_overall, "ucl": self.ucl,
             "lcl": self.lcl, "range_mean": self.range_mean, "range_ucl": self.range_ucl,
             "range_lcl": self.range_lcl, "lsl": self.lsl, "usl": self.usl, "cp": self.cp, "cpk": self.cpk,
             "pp": self.pp, "ppk": self.ppk, "outside": list(self.outside), "in_control": self.in_control,
             "violations": [v.to_dict() for v in self.violations]}
        if self.gauge_warnings:
            d["gauge_warnings"] = [w.to_dict() for w in self.gauge_warnings]
        if include_points:
            d["points"] = list(self.points)
            d["ranges"] = list(self.ranges)
        return d

    def report(self, unit: str = "kg·m²") -> str:
        def f(v: float | None, fmt: str = ".7g") -> str:
            return "n/a" if v is None else format(v, fmt)
        sub = f", subgroups of {self.subgroup}" if self.chart == "Xbar-R" else ""
        rname = "MR" if self.chart == "I-MR" else "R"
        L = [f"{self.chart} chart: {self.n_points} points{sub}",
             f"  centre      {f(self.mean)} {unit}   σ within {f(self.sigma_within, '.3g')}, overall "
             f"{f(self.sigma_overall, '.3g')}",
             f"  limits      LCL {f(self.lcl)}  UCL {f(self.ucl)}",
             f"  {rname:<3} chart    mean {f(self.range_mean, '.3g')}  LCL {f(self.range_lcl, '.3g')}  "
             f"UCL {f(self.range_ucl, '.3g')}",
             f"  capability  LSL {f(self.lsl)}  USL {f(self.usl)}   Cp {f(self.cp, '.3g')}  Cpk {f(self.cpk, '.3g')}"
             f"  Pp {f(self.pp, '.3g')}  Ppk {f(self.ppk, '.3g')}",
             f"  outside the limits: {', '.join(str(i + 1) for i in self.outside) or 'none'}"]
        if self.violations:
            L.append("  run rules: " + "; ".join(f"{v.rule} at point {v.index + 1}" for v in self.violations))
        else:
            L.append("  run rules: none violated")
        L.extend(f"  gauge: {w.message}" for w in self.gauge_warnings)
        return "\n".join(L)


def with_gauge(summary: SpcSummary, *, grr: GaugeRR | None = None, type1: Type1Study | None = None) -> SpcSummary:
    """``summary`` with the gauge studies' objections to its capability indices, judged at its own
    tolerance USL − LSL (unchanged without limits: there are no indices to object to)."""
    if summary.lsl is None or summary.usl is None or not summary.usl > summary.lsl:
        return summary
    return replace(summary, gauge_warnings=capability_warnings(grr=grr, type1=type1, tolerance=summary.usl - summary.lsl))


def c4(n: int) -> float:
    """The bias of a sample standard deviation of ``n`` normal values: E[s] = c4·σ."""
    return math.sqrt(2.0 / (n - 1)) * math.exp(math.lgamma(n / 2) - math.lgamma((n - 1) / 2))


def capability_interval(cp: float | None, cpk: float | None, n: int,
                        level: float = 0.95) -> dict[str, tuple[float, float] | None]:
    """The two-sided ``level`` confidence intervals of Cp and Cpk from ``n`` values (see the module docstring);
    None for an index that is missing or with fewer than 2 values."""
    from scipy.stats import chi2, norm

    out: dict[str, tuple[float, float] | None] = {"cp": None, "cpk": None}
    if n < 2:
        return out
    a = 1.0 - level
    nu = n - 1
    if cp is not None and math.isfinite(cp):
        out["cp"] = (cp * math.sqrt(float(chi2.ppf(a / 2, nu)) / nu), cp * math.sqrt(float(chi2.ppf(1 - a / 2, nu)) / nu))
    if cpk is not None and math.isfinite(cpk):
        half = float(norm.ppf(1 - a / 2)) * math.sqrt(1.0 / (9 * n) + cpk**2 / (2.0 * nu))
        out["cpk"] = (cpk - half, cpk + half)
    return out


def _capability(lsl: float | None, usl: float | None, mean: float, sigma: float) -> tuple[float | None, float | None]:
    if lsl is None or usl is None or not sigma > 0:
        return None, None
    return (usl - lsl) / (6 * sigma), min(usl - mean, mean - lsl) / (3 * sigma)


def _sample_std(values: Sequence[float]) -> float:
    m = sum(values) / len(values)
    return math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1))


def run_rules(points: Sequence[float], centre: float, sigma: float) -> list[Violation]:
    """The run-rule violations of a series of points (see the module docstring)."""
    out: list[Violation] = []
    side = [0 if p == centre else (1 if p > centre else -1) for p in points]
    for i, p in enumerate(points):
        if sigma > 0 and abs(p - centre) > 3 * sigma:
            out.append(Violation("beyond_limits", i))
        if i >= RUN_LENGTH - 1:
            window = side[i - RUN_LENGTH + 1: i + 1]
            if all(s == 1 for s in window) or all(s == -1 for s in window):
                out.append(Violation(f"run_of_{RUN_LENGTH}", i))
        if i >= TREND_LENGTH - 1:
            w = points[i - TREND_LENGTH + 1: i + 1]
            steps = [b - a for a, b in zip(w, w[1:])]
            if all(s > 0 for s in steps) or all(s < 0 for s in steps):
                out.append(Violation(f"trend_of_{TREND_LENGTH}", i))
        if i >= 2 and sigma > 0:
            w = points[i - 2: i + 1]
            for sgn in (1, -1):
                if sgn * (points[i] - centre) > 2 * sigma and sum(1 for q in w if sgn * (q - centre) > 2 * sigma) >= 2:
                    out.append(Violation("2_of_3_beyond_2sigma", i))
    return out


def individuals(values: Sequence[float], lsl: float | None = None, usl: float | None = None) -> SpcSummary:
    """I-MR chart of one value per part (at least 2)."""
    x = [float(v) for v in values]
    if len(x) < 2 or not all(math.isfinite(v) for v in x):
        raise SpcError(f"an individuals chart needs at least 2 finite values, got {len(x)}")
    c = chart_constants(2)
    mean = sum(x) / len(x)
    mr = [abs(b - a) for a, b in zip(x, x[1:])]
    mr_mean = sum(mr) / len(mr)
    sw = mr_mean / c["d2"]
    so = _sample_std(x)
    ucl, lcl = mean + 3 * sw, mean - 3 * sw
    cp, cpk = _capability(lsl, usl, mean, sw)
    pp, ppk = _capability(lsl, usl, mean, so)
    outside = tuple(i for i, v in enumerate(x) if v > ucl or v < lcl)
    return SpcSummary("I-MR", len(x), 1, tuple(x), tuple(mr), mean, sw, so, ucl, lcl, mr_mean, c["D4"] * mr_mean,
                      c["D3"] * mr_mean, lsl, usl, cp, cpk, pp, ppk, outside, tuple(run_rules(x, mean, sw)))


def _subgroups(subgroups: Sequence[Sequence[float]], chart: str) -> tuple[list[list[float]], int]:
    """The subgroups as floats and their one size; SpcError with fewer than 2 or sizes that differ."""
    groups = [[float(v) for v in g] for g in subgroups]
    if len(groups) < 2:
        raise SpcError(f"an {chart} chart needs at least 2 subgroups, got {len(groups)}")
    sizes = {len(g) for g in groups}
    if len(sizes) != 1:
        raise SpcError(f"{chart} needs subgroups of one size, got sizes "
                       f"{', '.join(str(n) for n in sorted(sizes))}")
    return groups, sizes.pop()


def xbar_s(subgroups: Sequence[Sequence[float]], lsl: float | None = None, usl: float | None = None) -> SpcSummary:
    """X̄–S chart of equal-size subgroups (2 … 25 values each, at least 2 subgroups); ``ranges``: the
    subgroups' standard deviations."""
    groups, n = _subgroups(subgroups, "X̄–S")
    if not 2 <= n <= SMALL_SAMPLE:
        raise SpcError(f"X̄–S needs subgroups of 2 to {SMALL_SAMPLE} values, got {n}")
    k = c4(n)
    means = [sum(g) / n for g in groups]
    sds = [_sample_std(g) for g in groups]
    xbb = sum(means) / len(means)
    sbar = sum(sds) / len(sds)
    sw = sbar / k
    so = _sample_std([v for g in groups for v in g])
    ucl, lcl = xbb + 3 * sw / math.sqrt(n), xbb - 3 * sw / math.sqrt(n)
    spread = 3 * math.sqrt(1 - k * k) / k
    cp, cpk = _capability(lsl, usl, xbb, sw)
    pp, ppk = _capability(lsl, usl, xbb, so)
    outside = tuple(i for i, v in enumerate(means) if v > ucl or v < lcl)
    return SpcSummary("Xbar-S", len(groups), n, tuple(means), tuple(sds), xbb, sw, so, ucl, lcl, sbar,
                      (1 + spread) * sbar, max(0.0, 1 - spread) * sbar, lsl, usl, cp, cpk, pp, ppk, outside,
                      tuple(run_rules(means, xbb, sw / math.sqrt(n))))


def xbar_r(subgroups: Sequence[Sequence[float]], lsl: float | None = None, usl: float | None = None) -> SpcSummary:
    """X̄–R chart of equal-size subgroups (2 … 10 values each, at least 2 subgroups)."""
    groups, n = _subgroups(subgroups, "X̄–R")
    c = chart_constants(n)
    means = [sum(g) / n for g in groups]
    ranges = [max(g) - min(g) for g in groups]
    xbb = sum(means) / len(means)
    rbar = sum(ranges) / len(ranges)
    sw = rbar / c["d2"]
    so = _sample_std([v for g in groups for v in g])
    ucl, lcl = xbb + c["A2"] * rbar, xbb - c["A2"] * rbar
    cp, cpk = _capability(lsl, usl, xbb, sw)
    pp, ppk = _capability(lsl, usl, xbb, so)
    outside = tuple(i for i, v in enumerate(means) if v > ucl or v < lcl)
    return SpcSummary("Xbar-R", len(groups), n, tuple(means), tuple(ranges), xbb, sw, so, ucl, lcl, rbar,
                      c["D4"] * rbar, c["D3"] * rbar, lsl, usl, cp, cpk, pp, ppk, outside,
                      tuple(run_rules(means, xbb, sw / math.sqrt(n))))
