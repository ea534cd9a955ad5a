"""SPC and the check standard's records: one recipe's control chart (I-MR, X̄–R or X̄–S) with Cp/Cpk and their
confidence interval, and the check standard's history with its individuals chart (also on the calibration
page)."""

from __future__ import annotations

import asyncio
import dataclasses
from typing import Any, Mapping

from aiohttp import web

from .. import quality as Q
from .pages import Family, Pages, Refused, history_filters
from .type1 import spc_gauge

#: the latest parts an SPC page charts at most
SPC_POINTS = 500
#: the control charts the SPC page draws
CHARTS = ("auto", "I-MR", "Xbar-R", "Xbar-S")
#: the charts' widths, px: a wide page's and a phone's
WIDE, NARROW = 720.0, 380.0


def check_standards(pages: Pages, filters: Mapping[str, Any], unit: str,
                    places: int | None = None) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
    """The check standard's history (`moi check-standard`) in the period, oldest first, and its control chart
    (individuals) from two checks on."""
    store = pages.app.store
    checks = [c for c in reversed(store.check_standards(limit=SPC_POINTS) if store is not None else [])
              if isinstance(c.get("value"), (int, float))
              and (filters.get("since") is None or c["finished_at"] >= filters["since"])
              and (filters.get("until") is None or c["finished_at"] < filters["until"])]
    check_chart = None
    if len(checks) >= 2:
        from measurement.spc import individuals

        summary = individuals([float(c["value"]) for c in checks])
        names = [f"{c.get('name') or 'check'} {pages.when(c['finished_at'])}" for c in checks]
        check_chart = {kind: Q.control_chart(summary, unit, width=w, names=names, places=places)
                       for kind, w in (("wide", WIDE), ("narrow", NARROW))}
    return checks, check_chart


def _design_words(grr: Any) -> tuple[str, str | None] | None:
    """The Gauge R&R's size in words, and why it is below the AIAG MSA design (``measurement.grr_design``)."""
    from measurement.grr_design import below_design, design

    return None if grr is None or grr.study is None else (design(grr.study), below_design(grr.study))


class SpcPages(Family):
    """``/spc``."""

    async def _compute(self, recipe: str, filters: Mapping[str, Any], chart: str) -> tuple[Any, str | None]:
        """The recipe's SPC (``recipe_spc``) off the loop, and a note when the chart asked for fell back to I-MR."""
        from measurement.errors import InvalidInput
        from service.parts.recipes import recipe_spc

        store, loop = self.app.store, asyncio.get_running_loop()

        def compute(kind: str) -> Any:
            return recipe_spc(store, recipe, since=filters["since"], until=filters["until"], chart=kind,
                              limit=SPC_POINTS)
        try:
            return await loop.run_in_executor(None, compute, chart), None
        except InvalidInput as exc:  # subgroups of unequal size (a release excluded), or of one release
            note = (f"{chart} cannot be drawn from these parts ({exc}): every part needs the same number of "
                    "usable releases. Shown as I-MR of the part values instead.")
            return await loop.run_in_executor(None, compute, "I-MR"), note

    async def _with_gauge(self, recipe: str, result: Any) -> tuple[Any, Any]:
        """``result`` with the gauge's objections to its Cp/Cpk (``measurement.spc.with_gauge``: %GRR above 30 %,
        ndc below 5) and the recipe's Gauge R&R they come from: the Gauge R&R page's study of all its records
        (``recipe_grr``; None: the records make none)."""
        from measurement.spc import with_gauge
        from service.parts.gauge_rr import recipe_grr

        store = self.app.store
        grr = await asyncio.get_running_loop().run_in_executor(None, lambda: recipe_grr(store, recipe))
        if grr.study is None:
            return result, None
        return dataclasses.replace(result, summary=with_gauge(result.summary, grr=grr.study)), grr

    def _unit(self, recipe: str) -> str:
        return self.pages.recipe_display(recipe)[0]

    def _places(self, recipe: str, summary: Any, unit: str) -> int:
        """The decimals of the recipe's values in ``unit``: its ``display_decimals``, else those of its limits
        (``quality.places``, the rule every page follows)."""
        lo, hi = getattr(summary, "lsl", None), getattr(summary, "usl", None)
        spec = {"nominal": (lo + hi) / 2, "upper": hi} if lo is not None and hi is not None else {}
        return Q.places({**spec, **self.pages.recipe_display(recipe)[1]}, unit)

    def _charts(self, result: Any, unit: str, places: int) -> tuple[dict[float, Any], dict[str, Any]]:
        """The control chart at both widths, and the capability's confidence interval."""
        from measurement.spc import SMALL_SAMPLE, capability_interval

        names = [f"{p or '(no ID)'} {self.pages.when(t)}" for p, t in zip(result.parts, result.finished)]
        charts = {w: Q.control_chart(result.summary, unit, width=w, names=names, places=places)
                  for w in (WIDE, NARROW)}
        s = result.summary
        values = s.n_points * s.subgroup
        capability = {"interval": capability_interval(s.cp, s.cpk, values), "n": values,
                      "small": values < SMALL_SAMPLE, "small_sample": SMALL_SAMPLE}
        return charts, capability

    async def spc(self, request: web.Request) -> web.Response:
        """Control chart (I-MR, X̄–R or X̄–S) of one recipe's part values, Cp/Cpk with their confidence interval, rule
        violations marked and said in words."""
        filters = history_filters(request)
        chart = request.query.get("chart", "auto")
        if chart not in CHARTS:
            raise Refused(400, f"chart={chart[:20]!r}: expected {', '.join(CHARTS)}")
        store = self.app.store
        recipes = store.recipes() if store is not None else []
        recipe = request.query.get("recipe", "").strip() or (recipes[-1] if recipes else "")
        if recipe and recipe not in recipes:
            raise Refused(404, f"no completed parts of recipe {recipe[:64]!r} in the store")
        result, note = await self._compute(recipe, filters, chart) if recipe else (None, None)
        result, grr = await self._with_gauge(recipe, result) if result is not None else (None, None)
        unit = self._unit(recipe)
        places = self._places(recipe, result.summary if result is not None else None, unit)
        charts, capability = self._charts(result, unit, places) if result is not None else (None, None)
        q = {"since": request.query.get("since", ""), "until": request.query.get("until", ""), "chart": chart}
        checks, check_chart = check_standards(self.pages, filters, unit)
        gauge1 = spc_gauge(store, recipe, result.summary) if result is not None else None  # the last Type 1 study
        return self.pages.page(request, "spc.html", title="SPC", recipes=recipes, recipe=recipe, spc=result,
                               chart=charts[WIDE] if charts else None, narrow=charts[NARROW] if charts else None,
                               note=note, capability=capability, charts=CHARTS, unit=unit, q=q, grr=grr,
                               checks=checks[-10:][::-1], check_chart=check_chart, type1=gauge1,
                               grr_design=_design_words(grr), places=places)
