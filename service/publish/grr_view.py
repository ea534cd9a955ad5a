"""What the Gauge R&R page and its PDF say: a recipe's study from the records (``service.parts.gauge_rr``) in
words and tables, every number in the recipe's display unit.

Values (the measurements, their means, the tolerance) are written with the recipe's decimals; standard
deviations (EV, AV, INT, GRR, PV, TV) and their 6σ study variations with one decimal more (a scatter is read
one digit finer than the values it comes from); sums of squares, mean squares and variances in the unit squared
with four significant digits; percentages to 0.1 %, p-values to 0.001 (AIAG's tables).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from measurement.gauge import (
    ACCEPTABLE,
    CONDITIONAL,
    GRR_ACCEPTABLE,
    GRR_CONDITIONAL,
    NDC_MIN,
    NOT_ACCEPTABLE,
    POOL_ALPHA,
    AnovaRow,
    GaugeRR,
)
from measurement.grr_design import below_design, cautions, design, parts_alike
from measurement.units import from_si
from service.parts.gauge_rr import BY, TRIALS, RecipeGrr

from . import quality as Q

#: the bands in the order of their severity, each with its words
BANDS = {ACCEPTABLE: f"acceptable (below {GRR_ACCEPTABLE:g} %)",
         CONDITIONAL: f"conditionally acceptable ({GRR_ACCEPTABLE:g} to {GRR_CONDITIONAL:g} %: the application and "
                      "the cost of the gauge decide)",
         NOT_ACCEPTABLE: f"not acceptable (above {GRR_CONDITIONAL:g} %)"}
#: the CSS class of each band (colour is never the only sign: the words are always written)
BAND_CLASS = {ACCEPTABLE: "verdict-OK", CONDITIONAL: "verdict-INVALID", NOT_ACCEPTABLE: "verdict-NOK"}
#: the variance components in the table's order: key, label
COMPONENTS = (("ev", "repeatability (EV, equipment)"), ("av", "reproducibility (AV, appraiser)"),
              ("interaction", "appraiser × part (INT)"), ("grr", "Gauge R&R (GRR)"), ("pv", "part-to-part (PV)"),
              ("tv", "total variation (TV)"))


@dataclass(frozen=True)
class Table:
    """A table as written: its header and rows of text; ``keys``: an id per row (the page's element ids)."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    keys: tuple[str, ...] = ()


@dataclass(frozen=True)
class Figure:
    """One figure of the verdict: its label, its text, its band (a key of ``BANDS``, or "" for none), its id and
    its value (None: not known)."""

    label: str
    text: str
    band: str
    key: str
    value: float | None = None


@dataclass(frozen=True)
class GrrView:
    """The study as the page and the PDF write it. headline/band: the verdict (band "" without figures);
    figures: %GRR of the process and of the tolerance, ndc; facts: (label, text); lacking: a line per part
    short of trials; notes: what else a reader should know; points: (part, appraiser, values in ``unit``)
    for the PDF's chart."""

    recipe: str
    unit: str
    headline: str
    band: str
    figures: tuple[Figure, ...]
    facts: tuple[tuple[str, str], ...]
    anova: Table | None
    anova_pooled: Table | None
    pooled: str
    components: Table | None
    data: Table | None
    counts: Table | None
    lacking: tuple[str, ...]
    notes: tuple[str, ...]
    points: tuple[tuple[str, str, tuple[float, ...]], ...]
    cautions: tuple[str, ...] = ()


def _study_of(g: RecipeGrr) -> str:
    a = len(g.appraisers)
    return (design(g.study) if g.study is not None
            else f"{len(g.parts)} part{'s' if len(g.parts) != 1 else ''} measured more than once × {a} "
                 f"appraiser{'s' if a != 1 else ''}")


def grr_view(g: RecipeGrr, unit: str, recipe: Mapping[str, Any] | None = None, time_format: str = Q.TIME_FORMAT,
             ) -> GrrView:
    """The words and tables of the study ``g`` in ``unit``; ``recipe``: its dict form with ``display_decimals``
    (the page's decimals; default: those that resolve a hundredth of the tolerance)."""
    spec = {**(g.spec or {}), **(recipe or {})}
    places = Q.places(spec, unit)
    s = g.study
    facts = [("recipe", f"{g.recipe}" + (f" ({spec['quantity']})" if spec.get("quantity") else "")),
             ("records", f"{g.read} measurement{'s' if g.read != 1 else ''}, {Q.local_time(g.first, time_format)} … "
                         f"{Q.local_time(g.last, time_format)}" if g.read else "none in the period"),
             ("appraisers", f"{BY[g.by]}: {', '.join(g.appraisers) or Q.MISSING}"),
             ("trial", TRIALS[g.trial]), ("study", _study_of(g))]
    if g.tolerance is not None:
        facts.append(("tolerance", f"{Q.inertia(g.tolerance, unit, places)} "
                                   f"({Q.inertia(spec.get('lower'), unit, places)} … "
                                   f"{Q.inertia(spec.get('upper'), unit, places)})"))
    else:
        facts.append(("tolerance", "none: the recipe has no two-sided limits (no %GRR of the tolerance)"))
    if s is not None:
        facts.append(("grand mean", Q.inertia(_grand_mean(s), unit, places)))
    figures, headline, band = _verdict(s, g.why)
    return GrrView(g.recipe, unit, headline, band, figures, tuple(facts),
                   _anova(s.anova, unit) if s is not None else None,
                   _anova(s.anova_pooled, unit) if s is not None and s.anova_pooled is not None else None,
                   _pooled_words(s) if s is not None else "", _components(s, unit, places) if s is not None else None,
                   _data(g, s, unit, places) if s is not None else None, _counts(g) if g.parts else None,
                   tuple(f"{p}: " + "; ".join(x.words for x in g.lacks(p)) for p in g.parts if g.lacks(p)),
                   _notes(g), _points(s, unit) if s is not None else (), cautions(s) if s is not None else ())


def _grand_mean(s: GaugeRR) -> float:
    flat = [v for part in s.values for cell in part for v in cell]
    return sum(flat) / len(flat)


def _verdict(s: GaugeRR | None, why: str | None) -> tuple[tuple[Figure, ...], str, str]:
    """The figures with their bands, the headline and its band (the worse of the two %GRRs; with parts all
    alike, %GRR of the tolerance alone: those against PV are meaningless, ``measurement.grr_design``)."""
    if s is None:
        return (), f"no Gauge R&R yet: {why}", ""
    alike = parts_alike(s)
    meaningless = " (meaningless: the parts do not span the process)" if alike else ""
    process = Figure("%GRR of the process variation (100·GRR/TV)", f"{Q.number(s.pct_grr_process, 1)} %{meaningless}",
                     "" if alike else s.verdict_process, "pct-process", s.pct_grr_process)
    pct_t, band_t = s.pct_grr_tolerance, s.verdict_tolerance
    tolerance = Figure(f"%GRR of the tolerance (100·{s.spread:g}·GRR/T)",
                       f"{Q.number(pct_t, 1)} %" if pct_t is not None else "– (no tolerance)", band_t or "",
                       "pct-tolerance", pct_t)
    ndc = s.ndc
    few = not alike and ndc is not None and ndc < NDC_MIN
    distinct = Figure("number of distinct categories (ndc = ⌊1.41·PV/GRR⌋)",
                      (str(ndc) if ndc is not None else "– (GRR is 0)")
                      + (meaningless if alike else f": fewer than {NDC_MIN}, the gauge cannot tell the parts apart"
                         if few else f" (at least {NDC_MIN} wanted)"), NOT_ACCEPTABLE if few else "", "ndc",
                      None if ndc is None else float(ndc))
    order = list(BANDS)
    judged = [f for f in (process, tolerance) if f.band]
    hedge = " (indicative: " + design(s) + ", below the AIAG MSA design)" if below_design(s) else ""
    if not judged:  # parts alike and no tolerance: nothing speaks of the gauge
        return (process, tolerance, distinct), ("no Gauge R&R verdict: the parts do not span the process and the "
                                                 "recipe has no tolerance" + hedge), ""
    worst = max(judged, key=lambda f: (order.index(f.band), f.value or 0.0))
    headline = f"Gauge R&R {BANDS[worst.band]}{hedge}: %GRR {worst.text} of the " + (
        "tolerance" if worst is tolerance else "process variation") + (
        f"; ndc {ndc}" if ndc is not None and not alike else "")
    return (process, tolerance, distinct), headline, worst.band


def _squared(x: float | None, unit: str) -> str:
    """A value in (kg·m²)² written in (``unit``)², four significant digits (the unit is in the table's header)."""
    f = from_si(1.0, unit) or 1.0
    return Q.MISSING if x is None else Q.number(x * f * f, ".4g")


def _anova(rows: tuple[AnovaRow, ...] | None, unit: str) -> Table:
    header = ("source", "df", f"SS ({unit})²", f"MS ({unit})²", "F", "p")
    out = []
    for r in rows or ():
        out.append((r.source, str(r.df), _squared(r.ss, unit), _squared(r.ms, unit) if r.ms is not None else "",
                    Q.number(r.f, ".4g") if r.f is not None else "", Q.number(r.p, 3) if r.p is not None else ""))
    return Table(header, tuple(out), tuple(r.source for r in rows or ()))


def _pooled_words(s: GaugeRR) -> str:
    p = next(r.p for r in s.anova if r.source == "appraiser × part")
    if s.pooled:
        return (f"the interaction is not significant (p = {Q.number(p, 3)} > {POOL_ALPHA:g}): pooled into "
                "repeatability; the components rest on the table without it")
    return (f"the interaction is significant (p = {Q.number(p, 3)} ≤ {POOL_ALPHA:g}): kept; the components rest on "
            "the table with it")


def _components(s: GaugeRR, unit: str, places: int) -> Table:
    """Each component's variance, its share of the total variance, σ, 6σ, % of TV and % of the tolerance."""
    header = ("source", f"variance ({unit})²", "% contribution", f"σ ({unit})", f"{s.spread:g}σ ({unit})",
              "% study variation", "% tolerance")
    f = from_si(1.0, unit) or 1.0
    rows = []
    for key, label in COMPONENTS:
        sigma = getattr(s, key)
        share = 100.0 * sigma ** 2 / s.tv ** 2 if s.tv > 0 else 0.0
        pct_t = s.pct_of_tolerance(sigma)
        rows.append((label, _squared(sigma ** 2, unit), Q.number(share, 1),
                     Q.number(sigma * f, places + 1), Q.number(s.spread * sigma * f, places + 1),
                     Q.number(s.pct_of_process(sigma), 1), Q.number(pct_t, 1) if pct_t is not None else Q.MISSING))
    return Table(header, tuple(rows), tuple(k for k, _ in COMPONENTS))


def _data(g: RecipeGrr, s: GaugeRR, unit: str, places: int) -> Table:
    """The study's values: a row per part, a column per appraiser and trial, and the part's mean."""
    f = from_si(1.0, unit) or 1.0
    header = ("part", *(f"{a} {t + 1}" for a in s.appraisers for t in range(s.trials)), f"mean ({unit})")
    rows = []
    for part, cells in zip(s.parts, s.values, strict=True):
        flat = [v for cell in cells for v in cell]
        rows.append((part, *(Q.number(v * f, places) for v in flat), Q.number(sum(flat) / len(flat) * f, places)))
    means = [sum(v for part in s.values for v in part[j]) / (len(s.parts) * s.trials) for j in range(len(s.appraisers))]
    rows.append(("appraiser mean", *(Q.number(m * f, places) if t == 0 else "" for m in means
                                     for t in range(s.trials)), Q.number(_grand_mean(s) * f, places)))
    return Table(header, tuple(rows), (*s.parts, "appraiser-means"))


def _counts(g: RecipeGrr) -> Table:
    """The trials each appraiser has of each part (of the ``trials`` the study uses)."""
    rows = []
    for p in g.parts:
        c = g.counts[p]
        rows.append((p, *(f"{c[a]} of {g.trials}" if c[a] != g.trials else str(c[a]) for a in g.appraisers),
                     "complete" if p in g.complete else "lacks trials"))
    return Table(("part", *g.appraisers, "in the figures"), tuple(rows), g.parts)


def _notes(g: RecipeGrr) -> tuple[str, ...]:
    out = []
    if g.beyond:
        out.append("trials beyond the study's " + str(g.trials) + " not used: "
                   + "; ".join(f"{x.part}, {x.words}" for x in g.beyond))
    if g.single:
        out.append(f"{g.single} part{'s' if g.single != 1 else ''} measured only once (production, not a study): "
                   "left out")
    if g.left_out:
        out.append(f"{g.left_out} measurement{'s' if g.left_out != 1 else ''} left out: INVALID, without a value or "
                   "without a part ID")
    others = [a for a in g.found if a not in g.appraisers]
    if others:
        out.append("appraisers not in this study: " + ", ".join(others))
    if g.truncated:
        out.append("only the latest measurements were read: narrow the period to see older ones")
    return tuple(out)


def _points(s: GaugeRR, unit: str) -> tuple[tuple[str, str, tuple[float, ...]], ...]:
    f = from_si(1.0, unit) or 1.0
    return tuple((p, a, tuple(v * f for v in cell)) for p, cells in zip(s.parts, s.values, strict=True)
                 for a, cell in zip(s.appraisers, cells, strict=True))
