"""The Type 1 gauge study's pages: the start form (the active recipe's reference part, x_ref and T in its display
unit, n), the running study's progress with Measure and Abort, a stored study's result (Cg, Cgk against 1.33,
x̄, s, the bias and its t-test, the smallest tolerance, the run chart) and its PDF. The study runs in the daemon
(``service.parts.gauge_study``), started and aborted through the command ``type1`` like every door's command."""

from __future__ import annotations

import asyncio
import json
import math
from typing import Any, Mapping

from aiohttp import web

from measurement.gauge import TYPE1_MIN, TYPE1_RECOMMENDED
from measurement.units import from_si
from service.core import vocabulary as V
from service.parts.gauge_study import RUNNING, TYPE1, Type1Record, running_study, type1_records
from service.publish.replies import CommandReply

from .. import quality as Q
from ..type1_report import places_of, release_flags, run_chart, type1_report_file, type1_words, value_places
from ..words import flag_name
from .pages import Family, Refused, action_form

#: how long a start waits for the daemon's answer, s
ANSWER_TIMEOUT = 10.0
#: the run chart's widths, px: a wide page's and a phone's (as the SPC page's)
WIDE, NARROW = 720.0, 380.0


def _number(form: Mapping[str, Any], key: str, what: str, unit: str) -> float | None:
    """A form's number in ``unit`` (a decimal comma taken) as kg·m²; None when empty."""
    text = str(form.get(key) or "").strip().replace(",", ".")
    if not text:
        return None
    try:
        v = float(text)
    except ValueError:
        raise Refused(400, f"{what}: {text[:30]!r} is not a number (in {unit})") from None
    if not math.isfinite(v):
        raise Refused(400, f"{what}: {text[:30]!r} is not a finite number")
    return v / (from_si(1.0, unit) or 1.0)


class Type1Pages(Family):
    """``/type1``, ``/type1/{uuid}``, its PDF, ``/api/type1`` and the start and abort actions."""

    def _unit(self, recipe: Any) -> str:
        return (recipe.display_unit if recipe is not None else None) or self.server.settings.display_unit

    async def _progress(self) -> dict[str, Any] | None:
        return await asyncio.wrap_future(self.app.call_soon(self.app.study_progress))

    def _record(self, uuid: str) -> Type1Record:
        if not uuid or len(uuid) > 64 or not all(c.isalnum() or c == "-" for c in uuid):
            raise Refused(400, f"bad study id {uuid[:64]!r}: expected a UUID")
        found = self.pages.store().gauge_studies(TYPE1, uuid=uuid, limit=1)
        if not found:
            raise Refused(404, f"no Type 1 study {uuid!r}")
        return Type1Record.from_dict(found[0])

    def _result(self, rec: Type1Record | None) -> dict[str, Any] | None:
        """What the page shows of a stored study: its words, the run chart at both widths, its releases."""
        if rec is None:
            return None
        settings = self.server.settings
        words = type1_words(rec, settings.display_unit, settings.time_format)
        unit, places = places_of(rec, settings.display_unit)
        f = from_si(1.0, unit) or 1.0
        flagged = release_flags(self.pages.store(), rec)
        rows = [(i + 1, u, Q.signed(Q.number(v * f, places)), [(x, flag_name(x)) for x in flagged[i]])
                for i, (u, v) in enumerate(zip(rec.releases, rec.values))]
        return {"rec": rec, "w": words, "chart": run_chart(rec, unit, WIDE, flagged=flagged, places=places),
                "narrow": run_chart(rec, unit, NARROW, flagged=flagged, places=places), "rows": rows,
                "flagged": sum(1 for fl in flagged if fl)}

    def _recipe(self, name: str) -> Any:
        """The recipe ``name`` names (a 400 saying why when none), or the active one for an empty name."""
        from measurement.errors import InvalidInput

        if not name:
            return self.app.parts.recipe
        try:
            return self.app.parts.book.find(name)
        except InvalidInput as exc:
            raise Refused(400, str(exc)) from None

    def _form(self, name: str) -> dict[str, Any]:
        """The start form's recipe (``name``'s, else the active one), its unit and defaults (x_ref: a check
        standard's certified value), and the recipes a study may be run for (those of one quantity)."""
        recipe = self._recipe(name)
        unit = self._unit(recipe)
        # the reference part: the last study's of this recipe, else the check standard's (never a production part's)
        last = type1_records(self.pages.store(), recipe.name, limit=1) if recipe is not None else []
        defaults: dict[str, Any] = {"count": TYPE1_RECOMMENDED, "reference": "", "tolerance": "",
                                    "part_id": (last[0].part_id or "") if last else ""}
        spec = recipe.spec if recipe is not None else None
        if recipe is not None and spec is not None:
            f = from_si(1.0, unit) or 1.0
            places = value_places(spec.upper - spec.lower, unit, recipe.display_decimals)
            defaults["tolerance"] = Q.number((spec.upper - spec.lower) * f, places)
            cs = recipe.check_standard
            if cs is not None:
                defaults["reference"] = Q.number(cs["reference"] * f, places)
                defaults["part_id"] = defaults["part_id"] or str(cs.get("name") or "")
        return {"recipe": recipe, "unit": unit, "defaults": defaults, "min": TYPE1_MIN,
                "tensor": recipe is not None and recipe.spec is None, "active": self.app.parts.recipe,
                "recipes": [r for r in self.app.parts.book.recipes if r.spec is not None]}

    def _plan(self, progress: Mapping[str, Any] | None) -> dict[str, str] | None:
        """The running study's x_ref and T as entered, in its unit and decimals (from the file the daemon keeps
        it in while it runs); None when none runs or its file is not there yet."""
        if progress is None or progress["status"] != RUNNING:
            return None
        rec = running_study(self.app.config.state_dir)
        if rec is None or rec.uuid != progress["uuid"]:
            return None
        facts = {k: text for k, _label, text in type1_words(rec, self.server.settings.display_unit).facts}
        return {"reference": facts["reference"], "tolerance": facts["tolerance"]}

    async def type1(self, request: web.Request) -> web.Response:
        progress = await self._progress()
        store = self.pages.store()
        recent = type1_records(store, limit=10)
        shown = None
        if progress is not None and progress["status"] != RUNNING:
            shown = next((r for r in recent if r.uuid == progress["uuid"]), None)
        elif progress is None and recent:
            shown = recent[0]
        return self.pages.page(request, "type1.html", title="Type 1 study", progress=progress, plan=self._plan(progress),
                               form=self._form(request.query.get("recipe", "").strip()), may=self.pages.may(request, "gauge"), result=self._result(shown),
                               recent=recent, blocked=self.pages.blocked())

    async def study(self, request: web.Request) -> web.Response:
        rec = self._record(request.match_info["uuid"])
        return self.pages.page(request, "type1.html", title=f"Type 1 study {rec.recipe}", progress=None, plan=None, form=None,
                               may=False, result=self._result(rec), recent=[], blocked=None)

    async def api(self, request: web.Request) -> web.Response:
        """The running (or last) study's progress and the newest stored study (kg·m²)."""
        progress = await self._progress()
        latest = type1_records(self.pages.store(), limit=1)
        body = {"study": progress, "latest": latest[0].to_dict() if latest else None}
        return web.json_response(body, dumps=lambda d: json.dumps(d, allow_nan=False))

    async def pdf(self, request: web.Request) -> web.Response:
        rec = self._record(request.match_info["uuid"])
        settings = self.server.settings
        body = await self.pages.in_child(type1_report_file, str(self.app.config.state_dir), rec.uuid,
                                         settings.display_unit, settings.time_format)
        return web.Response(body=body, content_type="application/pdf", headers={
            "Content-Disposition": f'attachment; filename="moi-type1-{rec.uuid[:8]}.pdf"'})

    async def _command(self, source: str, data: dict[str, Any]) -> CommandReply:
        """The study command queued, and the daemon's answer."""
        loop = asyncio.get_running_loop()
        answer: asyncio.Future[CommandReply] = loop.create_future()

        def settle(r: CommandReply) -> None:
            if not answer.done():  # a late answer after the time-out is dropped
                answer.set_result(r)

        def reply(r: CommandReply) -> None:  # on the daemon's main loop: handed to the web loop
            loop.call_soon_threadsafe(settle, r)
        self.app.command(V.TYPE1, source, data, reply)
        try:
            return await asyncio.wait_for(answer, ANSWER_TIMEOUT)
        except TimeoutError:
            raise Refused(503, f"the appliance did not answer within {ANSWER_TIMEOUT:g} s: try again") from None

    def _done(self, request: web.Request, form: Mapping[str, Any], r: CommandReply) -> web.Response:
        if r.status == "refused":
            raise Refused(400 if r.reason == "malformed" else 409, r.detail or r.reason or "refused")
        if "text/html" in request.headers.get("Accept", "") and form:
            raise web.HTTPSeeOther("/type1")
        return web.json_response({"accepted": True, "command": V.TYPE1, "status": r.status})

    async def start(self, request: web.Request) -> web.Response:
        """Start a study for the recipe named (default: the active one; selected first): x_ref and T in its
        display unit, n, the reference part's ID (set first)."""
        from measurement.errors import InvalidInput
        from service.parts.recipes import check_part_id

        form = await action_form(request)
        source = await self.pages.authorise(request, form, "gauge")
        recipe = self._recipe(str(form.get("recipe") or "").strip())
        unit = self._unit(recipe)
        data: dict[str, Any] = {"action": "start", "count": str(form.get("count") or TYPE1_RECOMMENDED).strip(),
                                "reference": _number(form, "reference", "reference value x_ref", unit),
                                "tolerance": _number(form, "tolerance", "tolerance T", unit)}
        part: dict[str, Any] = {}
        if recipe is not None and recipe is not self.app.parts.recipe:
            part["recipe"] = recipe.name
        part_id = str(form.get("part_id") or "").strip()
        if part_id != (self.app.parts.part_id or ""):
            try:
                part["part_id"] = check_part_id(part_id) or None
            except InvalidInput as exc:
                raise Refused(400, str(exc)) from None
        if part:  # the recipe and the part ID set first, in the command queue's order, unless that would end a run
            await self._may_select()
            self.app.command(V.RECIPE, source, part)
        return self._done(request, form, await self._command(source, data))

    async def _may_select(self) -> None:
        """A 409 when selecting the study's recipe or part would cut a study, a tensor set or a measurement short."""
        progress = await self._progress()
        if progress is not None and progress["status"] == RUNNING:
            raise Refused(409, f"a Type 1 study of {progress['recipe']} runs ({progress['done']} of "
                               f"{progress['count']}): abort it first")
        tensor = await asyncio.wrap_future(self.app.call_soon(self.app.set_progress))
        if tensor is not None and tensor.get("status") == RUNNING:
            raise Refused(409, f"a tensor set of {tensor['recipe']} runs: finish or abort it first")
        seq = self.app.sequencer
        if seq is not None and seq.busy:
            raise Refused(409, "a measurement runs: start the study when it is IDLE")

    async def abort(self, request: web.Request) -> web.Response:
        """Abort the running study: the quality role's, as its start is (an operator's press would throw away a
        quality engineer's study)."""
        form = await action_form(request)
        source = await self.pages.authorise(request, form, "gauge")
        return self._done(request, form, await self._command(source, {"action": "abort"}))



def spc_gauge(store: Any, recipe: str, summary: Any) -> dict[str, Any] | None:
    """SPC's Type 1 input: the last completed study of ``recipe`` (its record), its Cg and Cgk at the SPC's
    tolerance, and why the capability indices are not to be trusted with it (``capability_warnings``); None
    without a study."""
    from measurement.gauge import capability_warnings

    found = type1_records(store, recipe, "complete", 1) if recipe else []
    if not found or found[0].study is None:
        return None
    study = found[0].study
    usl, lsl = getattr(summary, "usl", None), getattr(summary, "lsl", None)
    tolerance = usl - lsl if usl is not None and lsl is not None else None
    T = tolerance if tolerance is not None else study.tolerance
    return {"record": found[0], "cg": study.cg_at(T), "cgk": study.cgk_at(T),
            "warnings": capability_warnings(type1=study, tolerance=tolerance)}
