"""An uncertainty budget as a person checks it by hand (the result page, the report page, the PDF): each line's
sensitivity with its unit, its contribution c·u in the page's unit, and shares of u² that are never negative
and sum to 100 %.

Two correlated inputs (the stiffness and the tare, fitted together) add the covariance 2·r·c₁u₁·c₂u₂ to u²;
alone, each line's (c·u)²/u² can then exceed 100 % with a negative covariance share beside it. Correlated
inputs are therefore one row: their (c·u)² and their covariance together, a variance and so never negative,
with their lines below it, each with its c·u but no share of its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from measurement.units import SI, from_si

if TYPE_CHECKING:  # pragma: no cover
    from measurement.uncertainty import Budget, Line

#: how the page and the PDF explain the shares
BUDGET_FOOTNOTE = ("share: the part of u² a row gives, (c·u)²/u², in %; the rows' shares sum to 100 %. Inputs that are "
            "correlated share one row: their (c·u)² and their covariance 2·r·c₁u₁·c₂u₂ together. "
            "contribution c·u = sensitivity c × standard uncertainty u.")


@dataclass(frozen=True)
class BudgetRow:
    """One row of a budget as shown. source: the line's, or the correlated group's ("A and B, correlated
    (r = …)"). share: % of u² (None: a line of a correlated group, whose row carries the share). contribution:
    c·u in kg·m² (a group's: the root of its variance, ≥ 0). line: the budget line (None: a group's row).
    member: a line shown below its group's row."""

    source: str
    share: float | None
    contribution: float
    line: Line | None = None
    member: bool = False

    def sensitivity(self, unit: str = SI) -> float | None:
        """c in ``unit`` per the input's unit (``per``); None for a group's row: c × u gives the contribution."""
        return from_si(self.line.sensitivity, unit) if self.line is not None else None

    @property
    def per(self) -> str:
        """The sensitivity's " per <the input's unit>" ("" for a dimensionless input or a group's row)."""
        return "" if self.line is None or self.line.unit in (None, "", "1") else f" per {self.line.unit}"


def _groups(budget: Budget) -> list[list[str]]:
    """The budget's symbols in groups joined by a correlation, in the order of the lines."""
    group = {ln.symbol: {ln.symbol} for ln in budget.lines}
    for c in budget.correlations:
        a, b = c.get("a"), c.get("b")
        if a in group and b in group and c.get("r") and group[a] is not group[b]:
            joined = group[a] | group[b]
            for s in joined:
                group[s] = joined
    out: list[list[str]] = []
    for ln in budget.lines:
        if not any(ln.symbol in g for g in out):
            out.append([s.symbol for s in budget.lines if s.symbol in group[ln.symbol]])
    return out


def budget_rows(budget: Budget | None) -> list[BudgetRow]:
    """The rows of a measurand's budget (``measurement.uncertainty.Budget``), shares in % of u²; [] without."""
    if budget is None:
        return []
    lines = {ln.symbol: ln for ln in budget.lines}
    r = {frozenset((c["a"], c["b"])): float(c["r"]) for c in budget.correlations if c.get("r")}
    var = budget.u ** 2
    rows: list[BudgetRow] = []
    for symbols in _groups(budget):
        members = [lines[s] for s in symbols]
        v = sum(ln.contribution ** 2 for ln in members)
        v += sum(2 * r.get(frozenset((a.symbol, b.symbol)), 0.0) * a.contribution * b.contribution
                 for i, a in enumerate(members) for b in members[i + 1:])
        share = 100.0 * max(v, 0.0) / var if var > 0 else 0.0
        if len(members) == 1:
            rows.append(BudgetRow(members[0].source, share, members[0].contribution, members[0]))
            continue
        pairs = ", ".join(f"r = {r[frozenset((a.symbol, b.symbol))]:+.3f}" for i, a in enumerate(members)
                          for b in members[i + 1:] if frozenset((a.symbol, b.symbol)) in r)
        rows.append(BudgetRow(" and ".join(ln.source for ln in members) + f", correlated ({pairs})", share,
                              math.sqrt(max(v, 0.0))))
        rows += [BudgetRow(ln.source, None, ln.contribution, ln, member=True) for ln in members]
    return rows
