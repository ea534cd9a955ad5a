"""Home and its actions: the operator's panel, the live state and its stream, Measure, Abort, the part in hand
and the guided tensor set."""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import json
import logging
from typing import Any

from aiohttp import web

from service.core import vocabulary as V
from service.parts.calibration import uncalibrated
from service.publish.payload import stored_result
from service.publish.replies import CommandReply
from service.states import STATES

from .. import quality as Q
from .drawing import axes_drawing
from .live import extras
from .pages import Family, Refused, action_form, read_form

log = logging.getLogger("moi.web")

#: a tick of the live stream every this many s (elapsed time, new samples)
TICK = 0.25
#: how long Measure waits for the daemon's answer (accepted or refused), s
ANSWER_TIMEOUT = 10.0


def _calibration(app: Any) -> dict[str, Any] | None:
    """The calibration as the next result will be judged, with the days it has left."""
    calibration = app.calibration_state()
    if calibration is not None and calibration.get("valid_until"):
        until = dt.date.fromisoformat(calibration["valid_until"])
        calibration = {**calibration, "days_left": (until - dt.datetime.now(dt.UTC).date()).days}
    return calibration


def _mode(open_part: dict[str, Any] | None, tile: Any, part_id: str | None, started: float,
          done_set: dict[str, Any] | None = None) -> str:
    """What the operator's panel shows big: the set's progress, the verdict, a finished tensor set, or ready for
    the next part."""
    # the verdict is shown big only for the part that owns it: none in progress, no other part ID set, and
    # finished since the daemon started (a restart forgets the part in hand: an older verdict is another part's)
    if open_part and open_part.get("done"):
        return "progress"
    if done_set is not None:  # a tensor set finished last: its part's, not an older part's of another recipe
        mine = done_set["finished_at"] >= started and (not part_id or part_id == done_set.get("part_id"))
        return "set_done" if mine else "ready"
    if tile is not None and tile.finished_at >= started and (not part_id or part_id == tile.part_id):
        return "verdict"
    return "ready"


def _done_set(store: Any, tile: Any) -> dict[str, Any] | None:
    """The latest stored tensor set when it finished after the latest part (the last thing finished), else None:
    its part, recipe, how it ended (complete, failed, aborted) and its flags."""
    latest = store.tensor_sets(1) if store is not None else []
    if not latest or latest[0].get("finished_at") is None:
        return None
    s = latest[0]
    if tile is not None and tile.finished_at > s["finished_at"]:
        return None
    tensor = s.get("tensor") or {}
    return {"uuid": s.get("uuid"), "part_id": s.get("part_id"), "recipe": s.get("recipe"),
            "status": str(s.get("status") or "–"), "flags": list(tensor.get("flags") or ()),
            "error": s.get("error"), "finished_at": s["finished_at"],
            "measured": sum(1 for v in (s.get("releases") or {}).values() if v), "skipped": len(s.get("skipped") or ())}


class HomePages(Family):
    """``/``, ``/home/summary``, ``/api/state``, ``/events``, the actions and the tensor set."""

    def summary(self) -> dict[str, Any]:
        """Home: the operator's panel (the part in hand: ready, in progress or its verdict; a calibration that
        refuses Measure), the shift's counters, the last parts and the calibration."""
        pages, store = self.pages, self.app.store
        shift = Q.shift_start(self.server.settings.shift_starts, dt.datetime.now().astimezone())
        parts = store.list(limit=12, parts_only=True, full=True) if store is not None else []
        last = store.latest("ok") if store is not None else None
        counts = store.verdict_counts(since=shift.timestamp()) if store is not None else {}
        live = extras(self.app)
        tracker = getattr(self.app, "parts", None)
        open_part = tracker.open_part if tracker is not None else None
        tile = parts[0] if parts else None
        tile_view = pages.decimals(Q.part_view(tile.payload, stored_result(tile.payload))) if tile else None
        tile_unit = pages.unit(tile.payload if tile else None)
        part_id = live.get("part_id")
        recipe = live.get("recipe") or {}
        left = None
        if open_part and (open_part.get("part_id") != part_id or open_part.get("recipe") != recipe.get("name")):
            left, open_part = open_part, None  # another part's: the next release abandons it
        done_set = _done_set(store, tile)
        mode = _mode(open_part, tile, part_id, pages.live.started, done_set)
        calibration = _calibration(self.app)
        return {"tile": tile, "tile_view": tile_view, "tile_unit": tile_unit, "counts": counts,
                "tile_places": Q.places((tile_view or {}).get("recipe"), tile_unit, (tile_view or {}).get("U")),
                "why": Q.judgement(tile_view, tile_unit) if tile_view else None,
                "tile_band": Q.band(tile_view["recipe"], tile_view.get("value"), tile_view.get("U"),
                                    tile_unit) if tile_view else None,
                "mode": mode, "part_id": part_id, "recipe": live.get("recipe"), "done_set": done_set,
                "repeat": bool(tile is not None and part_id and part_id == tile.part_id and mode == "verdict"),
                "shift": shift.strftime("%H:%M"), "strip": parts, "open_part": open_part, "left": left,
                "next_release": live.get("release_next"), "blocked": pages.blocked(),
                "calibration": calibration, "uncalibrated": uncalibrated(calibration), "last": last,
                "last_view": Q.part_view(last.payload, stored_result(last.payload)) if last else None,
                "last_unit": pages.unit(last.payload if last else None)}

    def _fault(self, request: web.Request) -> dict[str, Any]:
        """What Home says of a FAULT to the one reading it: what is wrong, and who acknowledges it: the quality
        role with Abort; an operator, who may not, is told whom to ask."""
        seq = self.app.sequencer
        may = self.pages.may(request, "acknowledge")
        contact = self.server.settings.contact
        do = ("Fix the cause, then acknowledge the fault with Abort: the release is measured again after it."
              if may else f"Do not measure: ask {contact} to acknowledge the fault once its cause is fixed.")
        return {"what": (seq.last_fault if seq is not None else None) or "no reason recorded", "do": do,
                "words": "fault: acknowledge it (Abort) once the cause is fixed" if may
                else f"fault: ask {contact} to acknowledge it"}

    async def _summary(self, request: web.Request) -> dict[str, Any]:
        """``summary()`` with the running tensor set's orientation to mount, or the running Type 1 study's count (read on
        the main loop, which owns them); in FAULT, the fault and who acknowledges it, whatever runs."""
        progress = await asyncio.wrap_future(self.app.call_soon(self.app.set_progress))
        study = await asyncio.wrap_future(self.app.call_soon(self.app.study_progress))
        s = self.summary()
        s["fault"] = self._fault(request)
        if self.app.live_status().state == "FAULT":
            s.update(mode="fault")  # never READY or "press Measure" under a FAULT heading
        elif progress is not None and progress.get("status") == "running" and progress.get("orientation"):
            o = progress["orientation"]
            s.update(mode="set", set=progress, drawing=axes_drawing(o["axis"], o.get("offset"), size=150))
        elif study is not None and study.get("status") == "running":
            # a study's releases are not parts: Home says whose they are, not the last part's verdict
            s.update(mode="study", study=study)
        return s

    async def home(self, request: web.Request) -> web.Response:
        return self.pages.page(request, "home.html", title="Home", state=self.pages.live.snapshot(),
                               s=await self._summary(request), recipes=self.app.parts.book.recipes)

    async def home_summary(self, request: web.Request) -> web.Response:
        """Home's operator panel, counters and last parts alone (the page fetches it after each result)."""
        html = self.pages.env.get_template("summary.html").render(s=await self._summary(request))
        return web.Response(text=html, content_type="text/html", headers={"Cache-Control": "no-store"})

    async def api_state(self, request: web.Request) -> web.Response:
        return web.json_response(self.pages.live.snapshot())

    # --- the live stream ----------------------------------------------------------------------------
    async def events(self, request: web.Request) -> web.StreamResponse:
        """Server-sent events: ``state`` on every transition, ``tick`` every 0.25 s (progress, new samples: none with
        ``?samples=no``); in a
        slot of its own (``streams``), for ``stream_lifetime`` at most, or until it yields its slot to another
        address's viewer or to a logged-in user's stream."""
        client = request.remote or "?"
        q = self.server.listen()
        slot = self.server.streams.take(client, self.pages.logged_in(request), end=lambda: q.put_nowait(None))
        if isinstance(slot, str):
            self.server.unlisten(q)
            refused = web.Response(status=503, text=f"no live stream now: {slot}", headers={"Retry-After": "10"})
            refused.force_close()  # a refused stream keeps no connection of the pages'
            return refused
        try:
            return await self._stream(request, q)
        finally:
            self.server.streams.give_back(slot)
            self.server.unlisten(q)

    async def _stream(self, request: web.Request, q: asyncio.Queue) -> web.StreamResponse:
        resp = web.StreamResponse(headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache",
                                           "X-Accel-Buffering": "no"})
        # the connection closes with the stream: an ended stream never holds its descriptor for a keep-alive
        resp.force_close()
        await resp.prepare(request)
        # a page that draws no swing (every page but Home) is sent no samples: a capture's are not written out
        # for it four times a second
        cursor: dict[str, Any] | None = None if request.query.get("samples") == "no" else {}
        loop = asyncio.get_running_loop()
        try:
            await resp.write(b"retry: 1000\n\n")
            next_tick = 0.0
            ends = loop.time() + self.server.settings.stream_lifetime
            while loop.time() < ends:
                timeout = max(0.0, next_tick - loop.time())
                try:
                    msg = await asyncio.wait_for(q.get(), timeout) if timeout > 0 else q.get_nowait()
                except (TimeoutError, asyncio.QueueEmpty):
                    msg = "tick"
                if msg is None:
                    break
                if msg == "tick":
                    next_tick = loop.time() + TICK
                    msg = self.pages.live.snapshot(cursor)
                await resp.write(f"event: {msg['type']}\ndata: {json.dumps(msg, allow_nan=False, default=str)}\n\n"
                                 .encode())
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        return resp

    # --- actions ------------------------------------------------------------------------------------
    async def _action(self, request: web.Request, name: str) -> web.Response:
        form = await action_form(request)
        state = self.app.live_status().state
        source = await self.pages.authorise(request, form,
                                            "acknowledge" if name == V.ABORT and state == "FAULT" else name)
        seq = self.app.sequencer
        if name == V.TRIGGER:
            blocked = self.pages.blocked()  # said at once; the daemon refuses it too, as at every door
            if blocked is not None:
                raise Refused(409, f"{blocked['what']} {blocked['do']}")
        if name == V.TRIGGER and seq is not None and seq.busy:
            # said, not queued and silently dropped: the sequencer takes no trigger while it measures; the state
            # read now, beside the refusal (a trigger taken but not yet started still reads IDLE)
            now = seq.state.value
            running = f"already running ({now})" if STATES[now].busy else "already requested and starting"
            raise Refused(409, f"a measurement is {running}: Measure again when it is IDLE")
        if name == V.TRIGGER:
            # the daemon's answer awaited: a trigger it refuses (FAULT, busy, blocked) is said at once in its words,
            # and the page never shows a measurement running that the daemon did not start
            r = await self._answer(name, source)
            if r.status == "refused":
                raise Refused(409, r.detail or r.reason or "refused")
        else:
            self.app.command(name, source)
        log.info("%s: %s requested (state %s)", source, name, state)
        if "text/html" in request.headers.get("Accept", "") and form:
            raise web.HTTPSeeOther("/")
        return web.json_response({"accepted": True, "command": name, "state": state}, status=202)

    async def _answer(self, name: str, source: str) -> CommandReply:
        """``name`` queued for the daemon, and its first answer (accepted or refused; a trigger's later outcome,
        done or failed, reaches the page through the live stream)."""
        loop = asyncio.get_running_loop()
        answer: asyncio.Future[CommandReply] = loop.create_future()

        def settle(r: CommandReply) -> None:
            if not answer.done():  # the run's outcome, or an answer after the time-out: the page has its own
                answer.set_result(r)

        def reply(r: CommandReply) -> None:  # on the daemon's main loop: handed to the web loop
            with contextlib.suppress(RuntimeError):  # the web server stopped meanwhile: nobody waits for it
                loop.call_soon_threadsafe(settle, r)
        self.app.command(name, source, None, reply)
        try:
            return await asyncio.wait_for(answer, ANSWER_TIMEOUT)
        except TimeoutError:
            raise Refused(503, f"the appliance did not answer within {ANSWER_TIMEOUT:g} s: nothing is known to "
                               "have started; look at the state before pressing again") from None

    async def measure(self, request: web.Request) -> web.Response:
        return await self._action(request, V.TRIGGER)

    async def abort(self, request: web.Request) -> web.Response:
        return await self._action(request, V.ABORT)

    async def part(self, request: web.Request) -> web.Response:
        """Select the recipe (name or number; 0 deselects) and/or set the part ID of the next measurements."""
        from measurement.errors import InvalidInput
        from service.parts.recipes import check_part_id

        form = await read_form(request)
        recipe = str(form.get("recipe") or "").strip()
        source = await self.pages.authorise(request, form, V.RECIPE if recipe else V.PART_ID)
        data: dict[str, Any] = {}
        if recipe:
            if recipe not in ("0",):
                try:
                    self.app.parts.book.find(recipe)
                except InvalidInput as exc:
                    raise Refused(400, str(exc)) from None
            data["recipe"] = recipe
        if "part_id" in form:
            try:
                data["part_id"] = check_part_id(str(form["part_id"])) or None
            except InvalidInput as exc:
                raise Refused(400, str(exc)) from None
        if not data:
            raise Refused(400, "nothing to change: give recipe and/or part_id")
        if self.app.sequencer is not None and self.app.sequencer.busy:
            raise Refused(409, "a measurement runs: the recipe and the part ID cannot change during it")
        self.app.command(V.RECIPE, source, data)
        return web.json_response({"accepted": True, "command": "part", **data}, status=202)

    # --- the guided tensor set ----------------------------------------------------------------------
    async def _set_state(self) -> tuple[dict[str, Any] | None, dict[str, Any] | None]:
        """The set's progress (read on the main loop, which owns it) and the latest stored tensor set."""
        progress = await asyncio.wrap_future(self.app.call_soon(self.app.set_progress))
        store = self.app.store
        latest = store.tensor_sets(1) if store is not None else []
        return progress, (latest[0] if latest else None)

    async def tensor_set(self, request: web.Request) -> web.Response:
        progress, latest = await self._set_state()
        o = (progress or {}).get("orientation")
        drawing = axes_drawing(o["axis"], o.get("offset")) if o else None
        return self.pages.page(request, "tensor_set.html", title="Tensor set", progress=progress, latest=latest,
                               drawing=drawing, s=self.summary())

    async def api_set(self, request: web.Request) -> web.Response:
        progress, latest = await self._set_state()
        return web.json_response({"set": progress, "latest": latest}, dumps=lambda d: json.dumps(d, default=str))

    async def set_action(self, request: web.Request) -> web.Response:
        """redo | skip | abort of the running tensor set (the same actions as the Modbus coils and MQTT)."""
        from service.parts.tensor_set import ACTIONS

        action = request.match_info["action"]
        if action not in ACTIONS:
            raise Refused(404, f"no set action {action!r}; expected one of {', '.join(ACTIONS)}")
        form = await action_form(request)
        source = await self.pages.authorise(request, form, "set")
        self.app.command(V.SET, source, {"action": action})
        log.info("web: set %s requested", action)
        if "text/html" in request.headers.get("Accept", "") and form:
            raise web.HTTPSeeOther("/set")
        return web.json_response({"accepted": True, "command": "set", "action": action}, status=202)
