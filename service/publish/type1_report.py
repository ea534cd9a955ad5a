"""A Type 1 gauge study as a person reads it, on its page and in its PDF (A4): the same facts in the recipe's
display unit and decimals, the verdict against 1.33, and the run chart (the values in their order, x_ref and
x_ref ± 0.1·T). The study itself: ``service.parts.gauge_study``; its statistics: ``measurement.gauge``."""

from __future__ import annotations

import datetime as dt
import io
from dataclasses import dataclass
from typing import Any, Sequence

from measurement.gauge import CG_LIMIT, TOLERANCE_SHARE
from measurement.units import SI, from_si
from service.parts.gauge_study import TYPE1, Type1Record, status_words

from . import quality as Q
from .words import flag_name

#: A4 portrait, inches
A4 = (8.27, 11.69)
CAPABLE, NOT_CAPABLE = "#1a7f37", "#b00020"


@dataclass(frozen=True)
class Type1Words:
    """What the page and the PDF say of a study: the head line, whether it is capable (None: no figures), the
    facts as (key, label, text) in the display unit (``unit``), and the notes."""

    head: str
    capable: bool | None
    facts: tuple[tuple[str, str, str], ...]
    notes: tuple[str, ...]
    unit: str
    places: int


def value_places(tolerance: float, unit: str, decimals: int | None) -> int:
    """The decimals of a value in ``unit``: the recipe's ``decimals``, else those that resolve a hundredth of
    the half ``tolerance`` (as a part's, ``quality.places``)."""
    return Q.places({"nominal": 0.0, "upper": tolerance / 2, "display_decimals": decimals}, unit)


def places_of(rec: Type1Record, default_unit: str = SI) -> tuple[str, int]:
    """The unit and the decimals a study's values are written with: its recipe's when it started (else the
    set-up's unit, and the decimals of its tolerance)."""
    unit = rec.unit or default_unit
    return unit, value_places(rec.plan.tolerance, unit, rec.decimals)


def type1_words(rec: Type1Record, default_unit: str = SI, time_format: str = Q.TIME_FORMAT) -> Type1Words:
    """The study ``rec`` in words. A scatter (s, the bias and its interval) gets one decimal more than a value:
    it is a fraction of the tolerance the values' decimals resolve to a hundredth."""
    unit, pl = places_of(rec, default_unit)
    fine = pl + 1

    def j(v: float | None, p: int = pl) -> str:
        return Q.inertia(v, unit, p)

    when = [Q.local_time(t, time_format) if t is not None else Q.MISSING for t in (rec.started_at, rec.finished_at)]
    facts = [("recipe", "recipe", f"{rec.recipe} ({rec.quantity}, version {rec.recipe_version or Q.MISSING})"),
             ("part", "reference part", rec.part_id or Q.MISSING),
             ("when", "measured", f"{when[0]} … {when[1]}, started by {rec.started_by or Q.MISSING}"),
             ("reference", "reference value x_ref", j(rec.plan.reference)),
             ("tolerance", "tolerance T", j(rec.plan.tolerance)),
             ("n", "measurements", f"{len(rec.values)} of {rec.plan.count}")]
    s = rec.study
    if s is None:
        head = "Type 1 study " + status_words(rec.status, rec.error)
        return Type1Words(head, None, tuple(facts), (), unit, pl)
    b = s.bias
    ci = f"{Q.number(100 * b.level, '.3g')} % interval {j(b.ci[0], fine)} … {j(b.ci[1], fine)}"
    facts += [("mean", "mean x̄", j(b.mean)),
              ("s", "standard deviation s", j(s.s, fine)),
              ("cg", "Cg = 0.2·T / (6·s)", f"{Q.number(s.cg, 2)} ({'≥' if s.cg >= CG_LIMIT else '<'} {CG_LIMIT})"),
              ("cgk", "Cgk = (0.1·T − |x̄ − x_ref|) / (3·s)",
               f"{Q.number(s.cgk, 2)} ({'≥' if s.cgk >= CG_LIMIT else '<'} {CG_LIMIT})"),
              ("bias", "bias x̄ − x_ref", f"{j(b.bias, fine)} ({ci})"),
              ("ttest", "t-test of the bias",
               f"t = {Q.number(b.t, 2)}, {b.dof} degrees of freedom, p = {Q.number(b.p, '.3g')}: "
               + (f"significant at {Q.number(100 * (1 - b.level), '.2g')} %" if b.significant else
                  f"not significant at {Q.number(100 * (1 - b.level), '.2g')} %")),
              ("tmin", "smallest tolerance at Cg = 1.33", j(s.min_tolerance_cg)),
              ("tmin_k", "smallest tolerance at Cgk = 1.33", j(s.min_tolerance_cgk)),
              ("limits", f"chart lines x_ref ± {Q.number(TOLERANCE_SHARE / 2, '.2g')}·T",
               f"{j(s.chart_lower)} … {j(s.chart_upper)}")]
    head = ("capable: Cg and Cgk at or above 1.33" if s.capable else
            "not capable: " + " and ".join(f for f, v in (("Cg", s.cg), ("Cgk", s.cgk)) if v < CG_LIMIT)
            + " below 1.33")
    return Type1Words(head, s.capable, tuple(facts), s.notes, unit, pl)


def run_chart(rec: Type1Record, unit: str, width: float = 720.0, height: float = 300.0,
              flagged: Sequence[Sequence[str]] = (), places: int | None = None) -> dict[str, Any] | None:
    """The run chart's SVG geometry (``quality.run_panel``) in ``unit`` with ``places`` decimals: the values,
    x_ref and x_ref ± 0.1·T; ``flagged``: each release's flags (a flagged release's point is marked)."""
    if not rec.values:
        return None
    f = from_si(1.0, unit) or 1.0
    half = TOLERANCE_SHARE / 2 * rec.plan.tolerance
    lines = [("x_ref", rec.plan.reference * f, "centre"), ("+0.1·T", (rec.plan.reference + half) * f, "spec"),
             ("−0.1·T", (rec.plan.reference - half) * f, "spec")]
    names = [f"measurement {i + 1}" + (f" (flags: {', '.join(flag_name(x) for x in flagged[i])})"
                                       if i < len(flagged) and flagged[i] else "") for i in range(len(rec.values))]
    bad = {i for i, fl in enumerate(flagged) if fl}
    return Q.run_panel([v * f for v in rec.values], lines, width, height, names, bad, places)


def type1_pdf(rec: Type1Record, default_unit: str = SI, time_format: str = Q.TIME_FORMAT,
              flagged: Sequence[Sequence[str]] = ()) -> bytes:
    """The study as a PDF: on its first A4 page the verdict, the facts, the run chart, signature lines; on the
    next the n values in their order with each release's flags (``flagged``)."""
    from matplotlib.backends.backend_pdf import PdfPages

    w = type1_words(rec, default_unit, time_format)
    buf = io.BytesIO()
    with PdfPages(buf, metadata={"Title": f"moi Type 1 study {rec.uuid}", "Subject": w.head}) as pdf:
        pdf.savefig(type1_page(rec, w, time_format, flagged))
        if rec.values:
            pdf.savefig(values_page(rec, w, flagged))
    return buf.getvalue()


def value_rows(rec: Type1Record, w: Type1Words, flagged: Sequence[Sequence[str]] = ()) -> list[tuple[int, str, str, str]]:
    """(k, the value in the study's unit and decimals, the release's uuid, its flags in words) per measurement."""
    return [(i + 1, Q.inertia(v, w.unit, w.places), u,
             ", ".join(flag_name(x) for x in flagged[i]) if i < len(flagged) else "")
            for i, (u, v) in enumerate(zip(rec.releases, rec.values))]


def values_page(rec: Type1Record, w: Type1Words, flagged: Sequence[Sequence[str]] = ()) -> Any:
    """The study's n values on A4, two columns, a flagged release marked with its flags."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=A4)
    fig.text(0.06, 0.965, f"Type 1 study {rec.uuid[:8]}: the {len(rec.values)} measurement{'s' if len(rec.values) != 1 else ''}", fontsize=12,
             weight="bold", va="top")
    rows = value_rows(rec, w, flagged)
    per_column = 50
    for k, (i, text, uuid, flags) in enumerate(rows):
        x, y = 0.06 + 0.46 * (k // per_column), 0.93 - 0.0165 * (k % per_column)
        fig.text(x, y, f"{i:>3}  {text}  ({uuid[:8]})" + (f"  flags: {flags}" if flags else ""), fontsize=7.5,
                 va="top", color="#9a6700" if flags else "k")
    fig.text(0.06, 0.03, f"moi Type 1 study · {rec.uuid}", fontsize=7.5, color="0.35")
    return fig


def type1_page(rec: Type1Record, w: Type1Words, time_format: str = Q.TIME_FORMAT,
               flagged: Sequence[Sequence[str]] = ()) -> Any:
    """The study's A4 page (a matplotlib ``Figure``): text stays text, so a PDF reader finds the figures."""
    import textwrap

    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    colour = "0.3" if w.capable is None else CAPABLE if w.capable else NOT_CAPABLE
    fig = Figure(figsize=A4)
    fig.text(0.06, 0.965, "Type 1 gauge study (VDA 5, AIAG MSA bias and repeatability)", fontsize=14,
             weight="bold", va="top")
    fig.text(0.06, 0.93, w.head, fontsize=15, weight="bold", color=colour, va="top")
    y = 0.885
    for _key, label, text in w.facts:
        wrapped = textwrap.wrap(text, 70) or [""]
        fig.text(0.06, y, label, fontsize=8.5, color="0.35", va="top")
        for line in wrapped:
            fig.text(0.40, y, line, fontsize=8.5, va="top")
            y -= 0.017
    if w.capable is not None:
        fig.text(0.06, y, f"values in {w.unit} with {w.places} decimal{'' if w.places == 1 else 's'}; s, the bias and "
                 "its interval with one more (a scatter)", fontsize=7.5, color="0.35", va="top")
        y -= 0.017
    for note in w.notes:
        for line in textwrap.wrap("note: " + note, 95):
            fig.text(0.06, y, line, fontsize=8.5, color="#9a6700", va="top")
            y -= 0.017
    if rec.values:
        _chart(fig, rec, w, y - 0.03, flagged)
    signatures = 0.12
    for x, who in ((0.06, "study run by (name, signature, date)"), (0.54, "accepted by quality (name, signature, date)")):
        fig.add_artist(Line2D([x, x + 0.4], [signatures, signatures], color="0.2", lw=0.8))
        fig.text(x, signatures - 0.008, who, fontsize=8, color="0.3", va="top")
    printed = dt.datetime.now().astimezone().strftime(time_format)
    fig.text(0.06, 0.03, f"moi Type 1 study · {rec.uuid}", fontsize=7.5, color="0.35")
    fig.text(0.94, 0.03, f"page 1 of 1 · printed {printed}", fontsize=7.5, color="0.35", ha="right")
    return fig


def _chart(fig: Any, rec: Type1Record, w: Type1Words, top: float, flagged: Sequence[Sequence[str]] = ()) -> None:
    """The run chart under the facts, down to above the signature lines; a flagged release's point marked."""
    from matplotlib.ticker import FuncFormatter

    unit = w.unit
    f = from_si(1.0, unit) or 1.0
    half = TOLERANCE_SHARE / 2 * rec.plan.tolerance
    ax = fig.add_axes((0.12, 0.2, 0.8, max(0.12, top - 0.22)))
    x = list(range(1, len(rec.values) + 1))
    ax.plot(x, [v * f for v in rec.values], "o-", color="#123", ms=3, lw=0.8, label="measurements")
    marked = [i for i, fl in enumerate(flagged) if fl and i < len(rec.values)]
    if marked:
        ax.plot([i + 1 for i in marked], [rec.values[i] * f for i in marked], "o", mfc="none", mec="#b00020", ms=7,
                label="flagged (see the list)")
    ax.axhline(rec.plan.reference * f, color="#1a7f37", lw=1.2, label="x_ref")
    for sign in (1, -1):
        ax.axhline((rec.plan.reference + sign * half) * f, color="#b00020", lw=1, ls="--",
                   label="x_ref ± 0.1·T" if sign > 0 else None)
    ax.set_xlabel("measurement, in the order taken", fontsize=8)
    ax.set_ylabel(f"{rec.quantity} [{unit}]", fontsize=8)
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: Q.signed(Q.number(v, w.places))))
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=4, frameon=False)
    ax.set_title("run chart", fontsize=9, loc="left")


def release_flags(store: Any, rec: Type1Record) -> list[tuple[str, ...]]:
    """Each counted release's flags, as stored (none for one no longer in the store)."""
    out = []
    for u in rec.releases:
        m = store.get(u)
        out.append(tuple(m.flags) if m is not None else ())
    return out


def type1_report_file(state_dir: str, uuid: str, default_unit: str, time_format: str | None = None) -> bytes:
    """The PDF of the stored study ``uuid`` (run in the web page's child process)."""
    from service.persistence.store import Store

    with Store(state_dir, read_only=True) as store:
        found = store.gauge_studies(TYPE1, uuid=uuid, limit=1)
        if not found:
            raise LookupError(f"no Type 1 study {uuid}")
        rec = Type1Record.from_dict(found[0])
        flagged = release_flags(store, rec)
    return type1_pdf(rec, default_unit, time_format or Q.TIME_FORMAT, flagged)

