"""The recipes page: every recipe as a quality engineer reads it, and the quality role's form to edit one."""

from __future__ import annotations

import asyncio
import datetime as dt
import logging
import math
from pathlib import Path
from typing import Any, Mapping
from urllib.parse import quote

from aiohttp import web

from measurement.units import INERTIA_UNITS
from service.errors import InputFileError
from service.parts.recipe_keys import EDITABLE
from service.parts.recipes import (
    RECIPE_AUDIT_FILE,
    Recipe,
    RecipeBook,
    RecipeEditError,
    RecipeError,
    audit_recipe,
    edit_recipe,
    recipe_values,
    recipe_version,
)

from .. import quality as Q
from .pages import Family, Refused, read_form

log = logging.getLogger("moi.web")


def _chosen_unit(typed: Mapping[str, str], shown: str, default: str) -> str:
    """The unit the form's inertias are read in: the display unit chosen in the same form ("": the set-up's), else
    the one the recipe is shown in (a unit the loader would refuse leaves the numbers as shown; it is refused)."""
    if "display_unit" not in typed:
        return shown
    chosen = typed["display_unit"].strip() or default
    return chosen if chosen in INERTIA_UNITS else shown


def largest_inertia(rig: Any, capture: float, min_swings: float) -> float | None:
    """The largest J (kg·m²) a torsion rig can measure: a part swings with T = 2π·√((J + J_tare)/k), and fewer than
    ``min_swings`` full swings in a capture of ``capture`` s is INVALID, so T ≤ capture/min_swings. None for another
    kind of rig or one without k (no clear bound)."""
    k = getattr(rig, "stiffness", None)
    if getattr(rig, "kind", None) != "torsion" or not k or min_swings <= 0:
        return None
    return k * (capture / min_swings / (2 * math.pi)) ** 2 - (getattr(rig, "tare_inertia", None) or 0.0)


class RecipePages(Family):
    """``/recipes``, shown and edited."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._editing = asyncio.Lock()  # one edit at a time: read, check the version, write, audit

    def _beyond_the_rig(self, recipe: Recipe, text: str | None, unit: str) -> str | None:
        """Why a nominal typed in ``unit`` is no moment of inertia this recipe's rig can measure (a number meant in
        another unit), or None (also when it is no number: the editor says so)."""
        nominal_key = next(k for k in EDITABLE if k.name == "nominal")
        try:
            nominal = nominal_key.parse(text or "", unit)
        except ValueError:
            return None
        rig = recipe.rig_for(self.app.config.rig)
        capture = self.app.config.sequencer.capture_duration
        most = largest_inertia(rig, capture, recipe.quality.min_swings)
        if nominal is None or most is None or nominal <= most:
            return None
        return (f"{Q.inertia(nominal, unit, '.6g')} is beyond what this rig measures: with k = {rig.stiffness:.4g} "
                f"N·m/rad a part above {Q.inertia(most, unit, '.3g')} swings fewer than "
                f"{recipe.quality.min_swings:g} full swings in the {capture:g} s capture (is the number in {unit}?)")

    async def recipes(self, request: web.Request, status: int = 200, **ctx: Any) -> web.Response:
        """Every recipe as a quality engineer reads it before measuring: nominal, tolerance, limits, releases,
        decision rule and quality rules, in the recipe's unit and decimals; for the quality role, a form per
        recipe to edit them, its inertias in the recipe's unit, with the version of the file it was opened on."""
        book = getattr(self.app, "parts", None)
        rows = []
        active = getattr(book, "recipe", None)
        for r in book.book.recipes if book is not None else ():
            d = {**r.to_dict(), "display_decimals": r.display_decimals}
            unit = Q.display_unit({"recipe": d}, self.server.settings.display_unit)
            rows.append({"r": d, "unit": unit, "places": Q.places(d, unit), "active": active is not None
                         and active.name == r.name, "rig": Path(r.rig_path).name if r.rig_path else None,
                         "file": recipe_values(r, unit), "version": recipe_version(r)})
        return self.pages.page(request, "recipes.html", status=status, title="Recipes", rows=rows,
                               editable=EDITABLE, may_edit=self.pages.may(request, "recipe"),
                               default_unit=self.server.settings.display_unit, units=INERTIA_UNITS,
                               saved=request.query.get("saved") if status == 200 else None, **ctx)

    async def recipes_change(self, request: web.Request) -> web.StreamResponse:
        """Edit one recipe's [recipe] keys (quality role): checked as a recipe file is, written back in one
        step, the running recipes re-read, and one line per edit appended to the recipe audit log. A refusal is
        said on the page beside the recipe, with what was typed."""
        form = await read_form(request)
        source = await self.pages.authorise(request, form, "recipe")
        parts = getattr(self.app, "parts", None)
        if parts is None or parts.book.directory is None:
            raise Refused(409, "no recipe directory ([recipes] directory): there is no recipe to edit")
        try:
            recipe = parts.book.find(str(form.get("recipe") or ""))
        except RecipeError as exc:
            raise Refused(404, str(exc)) from None
        typed = {k.name: str(form[k.name]) for k in EDITABLE if k.name in form}
        async with self._editing:
            return await self._edit(request, source, form, recipe, typed)

    async def _edit(self, request: web.Request, source: str, form: Any, recipe: Recipe,
                    typed: dict[str, str]) -> web.StreamResponse:
        """The edit itself, one at a time: a form opened on another version of the file is refused (409, and
        audited) with the recipe as it is now; a refused value is said by the field's label, every one."""
        parts = self.app.parts
        loop = asyncio.get_running_loop()
        audit = self.app.config.state_dir / RECIPE_AUDIT_FILE
        now = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
        if "version" in form and str(form["version"]) != recipe_version(recipe):
            await loop.run_in_executor(None, audit_recipe, audit, source, recipe,
                                       {"refused": ("the file changed since the form was opened", "nothing written")},
                                       now)
            return await self.recipes(request, status=409, edit_error={
                "recipe": recipe.name, "typed": {}, "errors": [("", "the recipe was changed since you opened it (by "
                                                                "someone else?): nothing was saved; here it is now, "
                                                                "edit it again if your change still holds")]})
        shown = Q.display_unit({"recipe": recipe.to_dict()}, self.server.settings.display_unit)
        unit = _chosen_unit(typed, shown, self.server.settings.display_unit)
        beyond = self._beyond_the_rig(recipe, typed.get("nominal"), unit)
        if beyond is not None:
            return await self.recipes(request, status=400, edit_error={
                "recipe": recipe.name, "typed": typed, "errors": [(f"nominal ({unit})", beyond)]})
        try:
            new, changes = await loop.run_in_executor(None, edit_recipe, recipe, typed, unit, shown)
        except RecipeEditError as exc:
            labels = {k.name: k.label_in(unit) for k in EDITABLE}
            errors = [(labels.get(k, "the recipe"), m) for k, m in exc.problems.items()]
            return await self.recipes(request, status=400, edit_error={"recipe": recipe.name, "errors": errors,
                                                                       "typed": typed})
        except (RecipeError, InputFileError) as exc:
            return await self.recipes(request, status=400, edit_error={"recipe": recipe.name, "typed": typed,
                                                                       "errors": [("the recipe file", str(exc))]})
        if changes:
            # the book swapped whole, the other recipes as they were read: a part already open keeps its recipe
            book = RecipeBook(parts.book.directory, tuple(new if r.name == new.name else r
                                                          for r in parts.book.recipes))
            parts.book = book
            if parts.recipe is not None and parts.recipe.name == new.name:
                parts.recipe = book.find(new.name)
            line = await loop.run_in_executor(None, audit_recipe, audit, source, new, changes, now)
            log.info("web: recipe edited: %s", line.strip())
        # the saved recipe shown back, its numbers in the unit chosen: said on the page beside it
        raise web.HTTPSeeOther(f"/recipes?saved={quote(new.name)}#recipe-{new.number}")
