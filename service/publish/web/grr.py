"""The Gauge R&R page and its PDF: a recipe's study from the appliance's own records (AIAG MSA 4th edition, ANOVA
method; ``service.parts.gauge_rr``), what a balanced study still lacks, and its figures in the recipe's unit."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any, Mapping

from aiohttp import web

from service.names import content_disposition
from service.parts.gauge_rr import BY, TRIALS, RecipeGrr, recipe_grr

from ..grr_view import BAND_CLASS, grr_view
from .child import grr_file
from .pages import Family, Refused, history_filters

#: the most trials per part and appraiser a study may ask for
MAX_TRIALS = 20


@dataclass(frozen=True)
class GrrQuery:
    """What the page was asked for: the recipe, the period (Unix s), who the appraisers are, what a trial is,
    which appraisers (None: all) and how many trials (None: the most common count); ``typed``: the form's
    fields as typed."""

    recipe: str
    since: float | None
    until: float | None
    by: str
    trial: str
    appraisers: tuple[str, ...] | None
    trials: int | None
    typed: Mapping[str, Any]

    def study_args(self) -> dict[str, Any]:
        """``recipe_grr``'s keyword arguments (plain values: they go to the child process too)."""
        return {"since": self.since, "until": self.until, "by": self.by, "trial": self.trial,
                "appraisers": None if self.appraisers is None else list(self.appraisers), "trials": self.trials}


def _choice(request: web.Request, name: str, choices: Mapping[str, str]) -> str:
    value = request.query.get(name, "").strip() or next(iter(choices))
    if value not in choices:
        raise Refused(400, f"{name}={value[:20]!r}: expected {' or '.join(choices)}")
    return value


def _trials(request: web.Request) -> int | None:
    text = request.query.get("trials", "").strip()
    if not text:
        return None
    if not text.isdigit() or not 2 <= int(text) <= MAX_TRIALS:
        raise Refused(400, f"trials={text[:20]!r}: expected a whole number of trials from 2 to {MAX_TRIALS}, or "
                           "nothing (the most common count)")
    return int(text)


class GrrPages(Family):
    """``/grr`` and ``/grr/report.pdf``."""

    def _recipes(self) -> tuple[list[str], str]:
        """The recipes a study may be of (those with completed parts, and the active one) and the default: the
        active recipe, else the latest measured."""
        store = self.app.store
        names = store.recipes() if store is not None else []
        parts = getattr(self.app, "parts", None)
        active = parts.recipe.name if parts is not None and parts.recipe is not None else None
        if active and active not in names:
            names.append(active)
        return names, active or (names[-1] if names else "")

    def _query(self, request: web.Request) -> tuple[GrrQuery, list[str]]:
        filters = history_filters(request)
        names, default = self._recipes()
        recipe = filters["recipe"] or default
        chosen = tuple(a.strip() for a in request.query.getall("appraiser", []) if a.strip())
        if any(len(a) > 128 for a in chosen):
            raise Refused(400, "appraiser: at most 128 characters")
        typed = {k: request.query.get(k, "") for k in ("since", "until", "by", "trial", "trials")}
        return GrrQuery(recipe, filters["since"], filters["until"], _choice(request, "by", BY),
                        _choice(request, "trial", TRIALS), chosen or None, _trials(request), typed), names

    async def _study(self, q: GrrQuery) -> RecipeGrr | None:
        """The recipe's study from the records, off the loop (None: no recipe to study)."""
        store = self.app.store
        if not q.recipe or store is None:
            return None
        return await asyncio.get_running_loop().run_in_executor(
            None, lambda: recipe_grr(store, q.recipe, **q.study_args()))

    async def grr(self, request: web.Request) -> web.Response:
        """The study: its records, what is missing for a balanced study, the ANOVA table, the variance
        components, %GRR of the process and of the tolerance, ndc and the verdict band."""
        q, names = self._query(request)
        g = await self._study(q)
        unit, shown = self.pages.recipe_display(q.recipe)
        view = grr_view(g, unit, shown, self.server.settings.time_format) if g is not None else None
        return self.pages.page(request, "grr.html", title="Gauge R&R", recipes=names, q=q, g=g, v=view, by=BY,
                               trial_words=TRIALS, band_class=BAND_CLASS, pdf=request.query_string)

    async def grr_pdf(self, request: web.Request) -> web.Response:
        """The study as a PDF (A4), made in the web page's child process from the same records."""
        q, _ = self._query(request)
        if not q.recipe:
            raise Refused(404, "no recipe to study: no parts measured with a recipe yet")
        unit, shown = self.pages.recipe_display(q.recipe)
        settings = self.server.settings
        body = await self.pages.in_child(grr_file, str(self.app.config.state_dir), q.recipe, q.study_args(), unit,
                                         shown, settings.time_format, self.app.config.device_id)
        name = f"moi-{self.app.config.device_id}-{q.recipe}-gauge-rr.pdf"
        return web.Response(body=body, content_type="application/pdf",
                            headers={"Content-Disposition": content_disposition(name)})
