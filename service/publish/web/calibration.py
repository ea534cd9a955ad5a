"""The calibration page: each rig's calibration, due date, stiffness and references, its history a page at a
time, the set-up's rig's reproducibility, and the check standard's history with its control chart."""

from __future__ import annotations

import asyncio
import datetime as dt
from pathlib import Path
from typing import Any

from aiohttp import web

from measurement.reproducibility import Reproducibility, for_release
from service.sources.calibrations import read_history, recorded_at
from service.sources.repeats import calibrated_since, rig_reproducibility

from .pages import Family, Refused
from .spc import check_standards


def _paging(query: Any) -> tuple[int, int | None]:
    """``?rig=N&before=BYTE``: the rig whose older calibrations are asked for (-1: none), and from where."""
    try:
        paged = int(query.get("rig", "-1"))
        before = int(query["before"]) if "before" in query else None
    except ValueError:
        raise Refused(400, "rig and before: expected whole numbers (the links of the history's pages)") from None
    if before is not None and before < 0:
        raise Refused(400, f"before={before}: expected a byte offset >= 0")
    return paged, before


class CalibrationPages(Family):
    """``/calibration`` and its banner."""

    async def calibration(self, request: web.Request) -> web.Response:
        """Each rig's calibration (date, due date, stiffness, the references it rests on), its history (every
        `moi calibrate`, newest first, a page at a time: ``service.sources.calibrations``) and the check
        standard's history with its control chart. ``?rig=N&before=BYTE``: rig N's older calibrations."""
        today = dt.datetime.now(dt.UTC).date()
        paged, before = _paging(request.query)
        loop = asyncio.get_running_loop()
        rows = []
        for i, (name, rig, used_by, path) in enumerate(self._rigs()):
            cal = rig.calibration
            until = cal.valid_until if cal is not None else None
            # the file is read off the loop: a long history must not hold every other page up
            history = await loop.run_in_executor(None, self._history, path, before if i == paged else None)
            # the store is the set-up's: its repeat releases tell the set-up's rig's scatter between releases
            repro = await loop.run_in_executor(None, self._reproducibility, cal) if i == 0 else None
            # what one release measured on this rig counts in its u: the history, else the calibration's, else the default
            counted = for_release(repro, rig.reproducibility)
            rows.append({"name": name, "used_by": used_by, "cal": cal, "until": until, "index": i, "repro": repro,
                         "repro_rig": rig.reproducibility, "repro_counted": counted,
                         "days_left": (until - today).days if until is not None else None,
                         "due": cal is not None and cal.due(today), "stiffness": rig.stiffness,
                         "stiffness_std": rig.stiffness_std, "paged": i == paged and before is not None, **history})
        unit = self.server.settings.display_unit
        checks, check_chart = check_standards(self.pages, {}, unit)
        return self.pages.page(request, "calibration.html", title="Calibration", rows=rows, unit=unit,
                               checks=checks[-20:][::-1], check_chart=check_chart,
                               state=self.app.calibration_state())

    async def banner(self, request: web.Request) -> web.Response:
        """The calibration's block as every page but Home shows it (``_banner.html``, empty when Measure may): an
        open page swaps it in when the live stream says the block came or went."""
        html = self.pages.env.get_template("_banner.html").render(blocked=self.pages.blocked())
        return web.Response(text=html, content_type="text/html", headers={"Cache-Control": "no-store"})

    def _reproducibility(self, cal: Any) -> Reproducibility | None:
        """The set-up's rig's scatter of ω_n between releases, pooled from the store's repeat releases since its
        calibration (None without a store)."""
        store = self.app.store
        if store is None:
            return None
        return rig_reproducibility(store, calibrated_since(cal))

    def _rigs(self) -> list[tuple[str, Any, list[str], str | None]]:
        """The set-up's rig and each recipe's own, once per rig file: (name, rig, recipes using it, its file)."""
        cfg = self.app.config
        book = getattr(self.app, "parts", None)
        rigs: list[tuple[str, Any, list[str], str | None]] = [("the set-up's rig", cfg.rig, [], cfg.rig_path)]
        seen = {Path(cfg.rig_path).resolve(): rigs[0]} if cfg.rig_path else {}
        for r in book.book.recipes if book is not None else ():
            if r.rig is None:
                continue
            key = Path(r.rig_path).resolve() if r.rig_path else None
            if key is not None and key in seen:
                seen[key][2].append(r.name)  # one rig file, several part types: one section
                continue
            rigs.append((Path(r.rig_path).name if r.rig_path else r.name, r.rig, [r.name], r.rig_path))
            if key is not None:
                seen[key] = rigs[-1]
        return rigs

    def _history(self, rig_path: str | None, before: int | None) -> dict[str, Any]:
        """A page of a rig file's calibration history as the page shows it: newest first, each line's time of
        writing in the page's local time, the damaged lines said, the offset of the older page."""
        if rig_path is None:
            return {"history": None, "history_file": None, "history_damaged": [], "history_older": None}
        h = read_history(rig_path, self.server.settings.page_size, before)
        return {"history": [e | {"recorded": self.pages.when(recorded_at(e))} for e in h.entries],
                "history_file": h.path.name, "history_damaged": h.damaged, "history_older": h.older}
