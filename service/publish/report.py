"""The quality record of one stored result as a PDF (A4): what the report page shows, drawn with
matplotlib's PDF backend (text stays text: a PDF reader finds the verdict)."""

from __future__ import annotations

import datetime as dt
import io
from typing import Any

from measurement.units import SI
from service.parts.calibration import uncalibrated

from . import quality as Q
from .budget import BUDGET_FOOTNOTE, BudgetRow
from .payload import stored_result
from .words import flag_name, flag_words

#: A4 portrait, inches
A4 = (8.27, 11.69)
VERDICT_COLOURS = {"OK": "#1a7f37", "NOK": "#b00020", "INVALID": "#9a6700"}


def report_lines(m: Any, unit: str, lookup: Any = None, time_format: str = Q.TIME_FORMAT,
                 decimals: int | None = None) -> tuple[dict[str, Any], list[tuple[str, str]], list[str]]:
    """(the part view, the (label, text) facts, the release lines) of a ``StoredMeasurement``; ``lookup(uuid)``:
    a release's stored measurement (its flags)."""
    p = m.payload or {}
    result = stored_result(p)
    v = Q.part_view(p, result)
    if v["recipe"] and decimals is not None:  # the recipe's display_decimals (not in the stored payload)
        v["recipe"] = {**v["recipe"], "display_decimals": decimals}
    r = v["recipe"] or {}
    cal = p.get("calibration") or None
    facts = [("measurement", f"#{m.seq} {m.uuid}"), ("part ID", p.get("part_id") or Q.MISSING),
             ("finished", Q.local_time(m.finished_at, time_format)), ("operator / started by", m.trigger or Q.MISSING),
             ("device", m.device_id), ("software", f"moi {m.software_version}")]
    pl = Q.places(r, unit, v.get("U") or v.get("std"))
    if r:
        facts.append(("recipe", f"{r.get('name')} (no. {r.get('number')}, version {r.get('version')})"))
        if r.get("lower") is not None:
            facts += [("nominal", Q.inertia(r.get("nominal"), unit, pl)),
                      ("limits", f"{Q.inertia(r.get('lower'), unit, pl)} … {Q.inertia(r.get('upper'), unit, pl)}"),
                      ("decision rule", "guard band (ISO 14253-1), unproven: " + str(r.get("uncertain"))
                       if r.get("rule") == "guard_band" else "simple acceptance (U reported, not used)")]
    if v.get("U") is not None:
        facts.append((f"{v.get('quantity') or 'J'} ± U", f"{Q.inertia(v.get('value'), unit, pl)} ± "
                      f"{Q.inertia(v.get('U'), unit, pl)} (k = {Q.number(v.get('k'), '.2g')})"))
        why = Q.judgement(v, unit) if v["kind"] == "part" else None
        if why and why["deviation"]:
            facts.append(("deviation", f"{why['deviation']} from the nominal, {why['where']}"))
    else:
        facts.append(("J ± u", f"{Q.inertia(v.get('value'), unit, pl)} ± {Q.inertia(v.get('std'), unit, pl)} (1σ)"))
    facts += [("  budget", _budget_line(row, unit)) for row in v["budget"]]
    if v["budget"]:
        facts.append(("", BUDGET_FOOTNOTE))
    cal = cal or {}
    facts.append(("calibration", (uncalibrated(cal or None) or f"{cal.get('date')}"
                                  + (f", due {cal.get('valid_until')}" if cal.get("valid_until") else ""))
                  + (" (DUE)" if cal.get("due") else "")))
    releases = []
    for r in Q.release_rows(v, p, result, lookup):
        flags = "flags: " + (", ".join(flag_name(f) for f in r["flags"]) or "none") if r["flags"] is not None else ""
        releases.append(f"release {r['index']} of {r['of']}: {Q.inertia(r['value'], unit, pl)} — "
                        f"{Q.reason(r['status'], unit, pl)}"
                        + (f"; {flags}" if flags else ""))
    described = [f"{flag_name(f)} ({f}): {words}" for f, words in flag_words(m.flags) if words]
    if described:
        releases.append("this release's flags: " + "; ".join(described))
    return v, facts, releases


def _budget_line(row: BudgetRow, unit: str) -> str:
    """A row of the uncertainty budget as the page writes it: c·u = c × u with their units, the share in %."""
    text = f"{'· ' if row.member else ''}{row.source}: c·u = {Q.inertia(row.contribution, unit, '.2g')}"
    ln = row.line
    if ln is not None:
        lu = "" if ln.unit in (None, "", "1") else " " + ln.unit
        text += f" (c = {Q.number(row.sensitivity(unit), '.3g')} {unit}{row.per}, u = {Q.number(ln.std, '.2g')}{lu})"
    return text + (f"; {Q.number(row.share, '.1f')} % of u²" if row.share is not None else "; share in the row above")


def report_pdf(m: Any, plot_png: bytes | None, unit: str = SI, lookup: Any = None,
               time_format: str = Q.TIME_FORMAT, decimals: int | None = None, study: str | None = None) -> bytes:
    """The report of the stored measurement ``m`` (``StoredMeasurement``) as PDF bytes, on as many A4 pages as
    it takes, each with "page x of y" and the print date (local, ``time_format``), the last with signature
    lines; ``plot_png``: the evidence plot kept with it (None: said on the page); ``study``: the Type 1 study that
    counted it, in words ("Type 1 study, 4 of 25": a reference part's release, no part's)."""
    import textwrap

    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    v, facts, releases = report_lines(m, unit, lookup, time_format, decimals)
    verdict = v.get("verdict")
    if study is not None:
        head, colour = f"{study} (the reference part: no part verdict)", "0.3"
    elif v["kind"] == "part":
        head, colour = v["verdict_words"], VERDICT_COLOURS.get(verdict or "", "k")
    elif v["kind"] == "release":
        head, colour = f"part in progress: release {v.get('index')} of {v.get('of')} (no part verdict yet)", "0.3"
    else:
        head, colour = "no recipe: a value without a verdict", "0.3"
    lines = [(k, t) for k, t in facts] + [("", "")] + [("", r) for r in releases]
    pl = Q.places(v["recipe"], unit, v.get("U") or v.get("std"))
    lines += [("", "why: " + Q.reason(r, unit, pl)) for r in v["reasons"]]
    figs: list[Any] = []
    fig = Figure(figsize=A4)
    fig.text(0.06, 0.965, f"Inertia measurement report #{m.seq}", fontsize=15, weight="bold", va="top")
    fig.text(0.06, 0.93, head, fontsize=20, weight="bold", color=colour, va="top")
    y = 0.885
    bottom = 0.08  # the footer (page x of y, print date) below
    for label, text in lines:
        wrapped = textwrap.wrap(text, 78) or [""]
        if y - 0.017 * len(wrapped) < bottom:  # the page is full: the rest on the next one
            figs.append(fig)
            fig = Figure(figsize=A4)
            fig.text(0.06, 0.965, f"report #{m.seq} ({head})", fontsize=9, va="top")
            y = 0.93
        fig.text(0.06, y, label, fontsize=8.5, color="0.35", va="top")
        for w in wrapped:
            fig.text(0.32 if label else 0.06, y, w, fontsize=8.5, va="top")
            y -= 0.017
    r = v["recipe"] or {}
    if y < 0.5:  # the band, the evidence and the signatures need room: a page of their own
        figs.append(fig)
        fig = Figure(figsize=A4)
        fig.text(0.06, 0.965, f"report #{m.seq} ({head})", fontsize=9, va="top")
        y = 0.93
    if r.get("lower") is not None and r.get("upper") is not None:
        y = _band(fig, y, r, v.get("value"), v.get("U"), unit)
    signatures = 0.14  # the signature lines above the footer
    if plot_png is not None:
        import matplotlib.image as mpimg

        ax = fig.add_axes((0.04, signatures + 0.02, 0.92, max(0.1, y - signatures - 0.06)))
        ax.imshow(mpimg.imread(io.BytesIO(plot_png), format="png"))
        ax.set_axis_off()
    else:
        fig.text(0.06, y - 0.02, "no evidence plot is kept with this measurement", fontsize=9, va="top")
    for x, who in ((0.06, "measured by (name, signature, date)"), (0.54, "released by quality (name, signature, date)")):
        fig.add_artist(Line2D([x, x + 0.4], [signatures, signatures], color="0.2", lw=0.8))
        fig.text(x, signatures - 0.008, who, fontsize=8, color="0.3", va="top")
    figs.append(fig)
    printed = dt.datetime.now().astimezone().strftime(time_format)
    buf = io.BytesIO()
    with PdfPages(buf, metadata={"Title": f"moi report {m.uuid}", "Subject": head}) as pdf:
        for i, page in enumerate(figs, start=1):
            page.text(0.06, 0.03, f"moi report #{m.seq} · {m.uuid}", fontsize=7.5, color="0.35")
            page.text(0.94, 0.03, f"page {i} of {len(figs)} · printed {printed}", fontsize=7.5, color="0.35",
                      ha="right")
            pdf.savefig(page)
    return buf.getvalue()


def _band(fig: Any, y: float, recipe: dict[str, Any], value: float | None, U: float | None, unit: str) -> float:
    """The tolerance band under the facts (as on the result page); returns the height left above it."""
    from measurement.units import from_si

    f = from_si(1.0, unit) or 1.0
    lsl, usl = recipe["lower"] * f, recipe["upper"] * f
    u = (U or 0.0) * f
    ax = fig.add_axes((0.08, y - 0.07, 0.84, 0.04))
    ax.axvspan(lsl, usl, color="#d8f5dc", label="tolerance zone")
    if recipe.get("rule", "guard_band") == "guard_band" and 0 < 2 * u < usl - lsl:
        ax.axvspan(lsl + u, usl - u, color="#8fd19e", label="proven in (guard band)")
    for x in (lsl, usl):
        ax.axvline(x, color="0.25", lw=1.5)
    span = usl - lsl
    lo, hi = lsl - 0.35 * span, usl + 0.35 * span
    if value is not None:
        x = value * f
        lo, hi = min(lo, x - u - 0.05 * span), max(hi, x + u + 0.05 * span)
        ax.errorbar([x], [0.5], xerr=[u], fmt="o", color="#123", capsize=4, label="result ± U")
    ax.set_xlim(lo, hi)
    ax.set_ylim(0, 1)
    ax.set_yticks([])
    ax.tick_params(labelsize=7)
    ax.set_xlabel(unit, fontsize=7)
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(0, 1.9), ncol=3, frameon=False)
    return y - 0.11
