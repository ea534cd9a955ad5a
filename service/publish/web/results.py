"""Results and history: one result's page, its quality record (page and PDF), its plot, trace, result and fit
files; the history's pages and its export files."""

from __future__ import annotations

import asyncio
import json
import math
from typing import TYPE_CHECKING, Any
from urllib.parse import urlencode

from aiohttp import web

from measurement.flags import FLAGS, describe
from service.errors import InputFileError
from service.names import content_disposition
from service.parts.calibration import uncalibrated
from service.publish.dfq import ENCODING
from service.publish.payload import stored_result

from .. import quality as Q
from ..words import flag_name, flag_words
from .child import export_file, replot, report_file, trace_file
from .pages import Family, Refused, history_filters, query_args
from .settings import PLOT_NAME

if TYPE_CHECKING:  # pragma: no cover
    from service.persistence.store import StoredMeasurement as Measurement

#: the largest history page asked for (its offset must stay an SQLite integer; no store has so many)
MAX_PAGE = 10**9
#: the export files, and their media types
EXPORTS = {"csv": "text/csv", "json": "application/json", "dfq": "text/plain"}


def _attachment(m: Measurement, tail: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="moi-{m.seq}-{m.uuid[:8]}{tail}"'}


class ResultPages(Family):
    """``/results/{key}`` and its files, ``/history`` and its exports."""

    def _context(self, m: Measurement) -> dict[str, Any]:
        """What the result and report pages share: the stored measurement ``m``, its payload ``p`` (the envelope's
        part keys) and its result ``r``, typed (None: a failed measurement, or a row of an older result schema)."""
        p = m.payload or {}
        r = stored_result(p)
        unit = self.pages.unit(p)
        view = self.pages.decimals(Q.part_view(p, r))
        if view["kind"] == "release" and m.part_uuid and self.app.store is not None:
            # an earlier release of a part that has been judged since: where its verdict is
            later = self.app.store.list(limit=50, part_id=m.part_id, recipe=m.recipe, parts_only=True)
            done = next((r for r in later if r.part_uuid == m.part_uuid), None)
            view["part_done"] = {"uuid": done.uuid, "seq": done.seq, "verdict": done.part_verdict} if done else None
        from service.parts.gauge_study import study_releases

        counted = study_releases(self.app.store, self.app.config.state_dir).get(m.uuid) if view["kind"] == "plain" \
            and self.app.store is not None else None
        return {"m": m, "p": p, "r": r, "unit": unit, "v": view, "study": counted, "band": Q.band(view["recipe"], view.get("value"),
                                                                           view.get("U"), unit),
                "places": Q.places(view["recipe"], unit, view.get("U") or view.get("std")),
                "why": Q.judgement(view, unit) if view["kind"] == "part" else None,
                # measured on a rig without a calibration record (said by the one rule), of a stored result alone
                "uncalibrated": uncalibrated(p["calibration"]) if m.status == "ok" and "calibration" in p else None}

    async def result(self, request: web.Request) -> web.Response:
        m = self.pages.measurement(request.match_info["key"])
        ctx = self._context(m)
        r = ctx["r"]
        steps = [s for s in r.steps if s.chosen] if r is not None else []
        return self.pages.page(request, "result.html", title=f"Result {m.seq}", steps=steps,
                               flags=flag_words(m.flags), baseline=r.baseline if r is not None else None,
                               has_trace=self.app.config.store_trace, **ctx)

    async def fit_json(self, request: web.Request) -> web.Response:
        """The fit and its residual of one of the latest results (the live page draws them over the swing)."""
        key = request.match_info["key"]
        fit = self.server.fit(key)
        if fit is None:
            m = self.pages.measurement(key)
            fit = self.server.fit(m.uuid)
        if fit is None:
            raise Refused(404, "only the latest results keep their fit for the live page; see the result's plot")
        return web.json_response(fit)

    async def report(self, request: web.Request) -> web.Response:
        """The quality record of one result: a page that prints on A4 (the PDF has the same content)."""
        m = self.pages.measurement(request.match_info["key"])
        ctx = self._context(m)
        releases = Q.release_rows(ctx["v"], m.payload, ctx["r"], self.pages.store().get)
        seen = sorted({f for r in releases for f in r["flags"] or ()} | set(m.flags))
        return self.pages.page(request, "report.html", title=f"Report {m.seq}", releases=releases,
                               flags=flag_words(seen), **ctx)

    async def report_pdf(self, request: web.Request) -> web.Response:
        m = self.pages.measurement(request.match_info["key"])
        fut = self.server.plot_future(m.uuid)
        if fut is not None:  # the evidence plot is being drawn: the report has it
            await asyncio.wrap_future(fut)
        decimals = self.pages.decimals(Q.part_view(m.payload))["recipe"] or {}  # the recipe's: no result read
        settings = self.server.settings
        body = await self.pages.in_child(report_file, str(self.app.config.state_dir), m.uuid, settings.display_unit,
                                         settings.time_format, decimals.get("display_decimals"))
        return web.Response(body=body, content_type="application/pdf", headers=_attachment(m, "-report.pdf"))

    async def plot(self, request: web.Request) -> web.Response:
        m = self.pages.measurement(request.match_info["key"])
        if m.status != "ok":
            raise Refused(404, f"measurement {m.seq} {m.status}: it has no result to plot")
        fut = self.server.plot_future(m.uuid)
        if fut is not None:
            await asyncio.wrap_future(fut)
        store = self.pages.store()
        got = store.get_attachment(m.uuid, PLOT_NAME)
        if got is None:
            # stored without a plot (the page was off): identify the kept trace again, once, and keep the picture
            if not store.has_trace(m.uuid):
                raise Refused(404, f"measurement {m.seq} has no plot and no stored trace to draw one from")
            cfg = self.app.config
            job = (replot, str(cfg.state_dir), m.uuid, cfg.rig.to_dict(), cfg.identification, cfg.simulated,
                   self.server.settings.display_unit)
            await asyncio.wrap_future(self.server.submit_plot(m.uuid, lambda: self.server.child.call(*job)))
            got = store.get_attachment(m.uuid, PLOT_NAME)
        data, media = got
        return web.Response(body=data, content_type=media, headers={"Cache-Control": "max-age=86400, immutable"})

    async def trace_csv(self, request: web.Request) -> web.Response:
        m = self.pages.measurement(request.match_info["key"])
        if not self.pages.store().has_trace(m.uuid):
            raise Refused(404, f"measurement {m.seq} was stored without its trace ([device] store_trace = false)")
        body = await self.pages.in_child(trace_file, str(self.app.config.state_dir), m.uuid)
        return web.Response(body=body, content_type="text/csv", headers=_attachment(m, "-trace.csv"))

    async def result_json(self, request: web.Request) -> web.Response:
        m = self.pages.measurement(request.match_info["key"])
        body = m.payload if m.payload is not None else {**m.summary(), "status": m.status}
        return web.Response(text=json.dumps(body, indent=2, ensure_ascii=False), content_type="application/json",
                            headers=_attachment(m, ".json"))

    # --- history --------------------------------------------------------------------------------------
    async def history(self, request: web.Request) -> web.Response:
        filters = history_filters(request)
        size = self.server.settings.page_size
        try:
            page = int(request.query.get("page", "1"))
        except ValueError:
            raise Refused(400, f"page={request.query.get('page', '')[:20]!r}: expected a page number 1, 2, ...") from None
        if not 1 <= page <= MAX_PAGE:
            raise Refused(400, f"page: expected a page number 1, 2, ... (at most {MAX_PAGE})")
        rows, total = self.pages.store().search(offset=(page - 1) * size, limit=size, **filters)
        pages = max(1, math.ceil(total / size))
        if page > pages:
            raise Refused(404, f"page {page}: the history has {pages} page{'s' if pages != 1 else ''} of {size} "
                               f"({total} measurement{'s' if total != 1 else ''}{' match' if any(filters.values()) else ''})")
        args = {k: v for k, v in query_args(request).items() if v}

        def link(n: int) -> str:
            return "/history?" + urlencode({**args, "page": n})

        from service.parts.gauge_study import study_releases

        flag_names = [(f, flag_name(f), w) for f, w in flag_words(sorted(FLAGS))]
        return self.pages.page(request, "history.html", title="History", rows=rows, total=total, page=page,
                               pages=pages, unit=self.server.settings.display_unit, flag_meaning=describe,
                               studied=study_releases(self.pages.store(), self.app.config.state_dir),
                               unit_of=self.pages.unit, places_of=self.pages.places, q=query_args(request), link=link, export=urlencode(args),
                               flag_names=flag_names, recipes=self.pages.store().recipes())

    async def export(self, request: web.Request) -> web.Response:
        fmt = request.match_info["fmt"]
        if fmt not in EXPORTS:
            raise Refused(404, f"export format {fmt[:10]!r}: expected export.csv, export.json or export.dfq")
        filters = history_filters(request)
        if fmt == "dfq" and not filters["recipe"]:
            raise Refused(400, "a DFQ file holds one part type: give recipe=NAME")
        name = f"moi-{self.app.config.device_id}-{filters['recipe'] if fmt == 'dfq' else 'history'}.{fmt}"
        # the same files as `moi export` (oldest first)
        try:
            body = await self.pages.in_child(export_file, str(self.app.config.state_dir), fmt, filters)
        except InputFileError as exc:  # no parts of that recipe
            raise Refused(404, str(exc)) from None
        if fmt == "csv":  # a byte-order mark: Excel on Windows reads the file as UTF-8 (kg·m², not kgÂ·mÂ²)
            body = "\ufeff".encode() + body
        return web.Response(body=body, content_type=EXPORTS[fmt], charset="utf-8" if fmt != "dfq" else ENCODING,
                            headers={"Content-Disposition": content_disposition(name)})
