"""A Gauge R&R study as a PDF (A4): what the Gauge R&R page shows (``grr_view.GrrView``), drawn with matplotlib's PDF
backend (text stays text: a PDF reader finds the figures), with the values by part and appraiser as a chart."""

from __future__ import annotations

import datetime as dt
import io
import textwrap
from typing import Any

from . import quality as Q
from .grr_view import GrrView, Table
from .report import A4

#: the colour of each verdict band (as the page's)
BAND_COLOURS = {"acceptable": "#1a7f37", "conditional": "#9a6700", "not acceptable": "#b00020"}
#: the page's margins and its text's height per line (fractions of the page)
LEFT, TOP, BOTTOM, LINE = 0.06, 0.93, 0.08, 0.0165
#: a character's width at 8 pt (fraction of the page's width), to set a table's columns
CHAR = 0.0076


class _Flow:
    """Text flowing down A4 pages: a new page when the next block does not fit."""

    def __init__(self, head: str) -> None:
        from matplotlib.figure import Figure

        self._figure = Figure
        self.head = head
        self.figs: list[Any] = []
        self.fig = Figure(figsize=A4)
        self.y = TOP

    def need(self, height: float) -> None:
        if self.y - height < BOTTOM:
            self.figs.append(self.fig)
            self.fig = self._figure(figsize=A4)
            self.fig.text(LEFT, 0.965, self.head, fontsize=9, va="top")
            self.y = TOP

    def line(self, label: str, text: str, size: float = 8.5, **kw: Any) -> None:
        wrapped = textwrap.wrap(text, int((80 if label else 100) * 8.5 / size)) or [""]
        self.need(LINE * size / 8.5 * len(wrapped))
        if label:
            self.fig.text(LEFT, self.y, label, fontsize=size, color="0.35", va="top")
        for w in wrapped:
            self.fig.text(0.3 if label else LEFT, self.y, w, fontsize=size, va="top", **kw)
            self.y -= LINE * max(1.0, size / 8.5)

    def heading(self, text: str) -> None:
        self.need(3 * LINE)
        self.y -= 0.4 * LINE
        self.fig.text(LEFT, self.y, text, fontsize=10.5, weight="bold", va="top")
        self.y -= 1.3 * LINE

    def table(self, t: Table, size: float = 7.5) -> None:
        """The table with its columns as wide as their longest text."""
        widths = [max(len(r[i]) for r in (t.header, *t.rows)) + 2 for i in range(len(t.header))]
        scale = min(1.0, (1 - 2 * LEFT) / (CHAR * size / 8 * sum(widths)))
        xs = [LEFT]
        for w in widths[:-1]:
            xs.append(xs[-1] + w * CHAR * size / 8 * scale)
        for k, row in enumerate((t.header, *t.rows)):
            self.need(LINE)
            for x, cell in zip(xs, row, strict=True):
                self.fig.text(x, self.y, cell, fontsize=size * min(1.0, scale + 0.15), va="top",
                              weight="bold" if k == 0 else "normal")
            self.y -= LINE * 0.95


def grr_pdf(v: GrrView, device_id: str, time_format: str = Q.TIME_FORMAT) -> bytes:
    """The study ``v`` as PDF bytes, on as many A4 pages as it takes, each with "page x of y" and the print date
    (local, ``time_format``), the last with signature lines."""
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.lines import Line2D

    flow = _Flow(f"Gauge R&R, recipe {v.recipe}, {device_id}")
    flow.fig.text(LEFT, 0.965, f"Gauge R&R of recipe {v.recipe} (AIAG MSA 4th edition, ANOVA method)", fontsize=14,
                  weight="bold", va="top")
    flow.line("", v.headline, size=12, weight="bold", color=BAND_COLOURS.get(v.band, "0.3"))
    for text in v.cautions:
        flow.line("", text, color="#9a6700")
    flow.y -= 0.5 * LINE
    for label, text in v.facts:
        flow.line(label, text)
    for f in v.figures:  # labels too long for the facts' column: a line each
        flow.line("", f"{f.label}: {f.text}" + (f" ({f.band})" if f.band else ""), weight="bold")
    for title, table in (("ANOVA (with the interaction)", v.anova), ("ANOVA (the interaction pooled)", v.anova_pooled),
                         (f"Variance components ({v.unit})", v.components)):
        if table is not None:
            flow.heading(title)
            flow.table(table)
            if title.startswith("ANOVA (with"):
                flow.line("", v.pooled, size=8)
    if v.lacking:
        flow.heading("Missing for a balanced study (not in the figures)")
        for text in v.lacking:
            flow.line("", text)
    if v.notes:
        flow.heading("Notes")
        for text in v.notes:
            flow.line("", text)
    if v.points:
        flow.need(0.33)
        _chart(flow.fig, flow.y - 0.3, v)
        flow.y -= 0.33
    if v.data is not None:
        flow.heading(f"Values ({v.unit})")
        flow.table(v.data, size=7)
    flow.need(0.09)
    signatures = flow.y - 0.05
    for x, who in ((LEFT, "study run by (name, signature, date)"), (0.54, "accepted by quality (name, signature, date)")):
        flow.fig.add_artist(Line2D([x, x + 0.4], [signatures, signatures], color="0.2", lw=0.8))
        flow.fig.text(x, signatures - 0.008, who, fontsize=8, color="0.3", va="top")
    flow.figs.append(flow.fig)
    printed = dt.datetime.now().astimezone().strftime(time_format)
    buf = io.BytesIO()
    with PdfPages(buf, metadata={"Title": f"moi Gauge R&R {v.recipe}", "Subject": v.headline}) as pdf:
        for i, page in enumerate(flow.figs, start=1):
            page.text(LEFT, 0.03, f"moi {device_id} · Gauge R&R · {v.recipe}", fontsize=7.5, color="0.35")
            page.text(0.94, 0.03, f"page {i} of {len(flow.figs)} · printed {printed}", fontsize=7.5, color="0.35",
                      ha="right")
            pdf.savefig(page)
    return buf.getvalue()


def _chart(fig: Any, bottom: float, v: GrrView) -> None:
    """The values by part, a marker per appraiser (the parts' spread against the appraisers' and trials')."""
    ax = fig.add_axes((0.1, bottom + 0.04, 0.84, 0.24))
    parts = list(dict.fromkeys(p for p, _, _ in v.points))
    appraisers = list(dict.fromkeys(a for _, a, _ in v.points))
    markers = "os^Dvx*P"
    width = 0.6 / max(1, len(appraisers))
    for j, a in enumerate(appraisers):
        xs, ys = [], []
        for p, who, values in v.points:
            if who == a:
                xs += [parts.index(p) + (j - (len(appraisers) - 1) / 2) * width] * len(values)
                ys += list(values)
        ax.plot(xs, ys, markers[j % len(markers)], ms=4, label=a, alpha=0.8)
    ax.set_xticks(range(len(parts)), parts, fontsize=7, rotation=30 if len(parts) > 8 else 0)
    ax.tick_params(labelsize=7)
    ax.ticklabel_format(axis="y", style="plain", useOffset=False)  # the values as the tables write them
    ax.set_ylabel(v.unit, fontsize=8)
    ax.set_title("values by part and appraiser", fontsize=9)
    ax.legend(fontsize=7, ncol=min(4, len(appraisers)), loc="best")
