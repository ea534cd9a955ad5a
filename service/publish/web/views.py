"""Pages and endpoints. Every bad request gets a 4xx with a sentence saying what was wrong; an
unexpected error is logged and answered 500 with its type, never with a traceback."""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import hashlib
import hmac
import json
import logging
import math
import secrets
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Protocol
from urllib.parse import urlencode, urlsplit

import jinja2
from aiohttp import web

from measurement.errors import VisionError
from measurement.flags import FLAGS
from measurement.reproducibility import Reproducibility
from service import __version__
from service.core import vocabulary as V
from service.errors import InputFileError, StoreDamaged
from service.names import content_disposition
from service.parts.recipe_keys import EDITABLE
from service.parts.recipes import (
    PART_ID_LENGTH,
    RECIPE_AUDIT_FILE,
    RecipeBook,
    RecipeError,
    audit_recipe,
    edit_recipe,
    recipe_values,
)
from service.publish.dfq import ENCODING
from service.publish.payload import stored_result
from service.sources.calibrations import read_history, recorded_at
from service.sources.repeats import rig_reproducibility
from service.states import vocabulary

from .. import quality as Q
from ..words import STATE_WORDS, flag_words
from .auth import (
    COOKIE,
    CSRF_HEADER,
    GUESS_DELAY,
    LOCKOUT_TIME,
    LOCKOUT_WINDOW,
    LOCKOUT_WRONG,
    LOGIN_COOKIE,
    MAX_USER_NAME,
    MIN_PASSWORD,
    ROLES,
    SESSION_LIFETIME,
    SOURCE_WRONG,
    User,
    allowed,
    check_user,
    hash_password,
    save_users,
    throttled_words,
)
from .child import ChildBusy, export_file, replot, report_file, trace_file
from .live import Live, extras
from .priority import CaptureFirst, sensor_is_read
from .settings import PLOT_NAME

if TYPE_CHECKING:  # pragma: no cover
    import concurrent.futures

    from service.persistence.store import Store
    from service.persistence.store import StoredMeasurement as Measurement
    from service.publish.port import ApplianceView

    from .auth import Guard
    from .child import ChildWork
    from .settings import WebSettings
    from .streams import StreamSlots

    class WebServer(Protocol):
        """What the views use of the server that owns them (``server.WebServer``)."""

        appliance: ApplianceView
        settings: WebSettings
        guard: Guard
        child: ChildWork
        streams: StreamSlots

        def listen(self) -> asyncio.Queue: ...
        def unlisten(self, q: asyncio.Queue) -> None: ...
        def plot_future(self, uuid: str) -> concurrent.futures.Future | None: ...
        def submit_plot(self, uuid: str, get_result: Any) -> concurrent.futures.Future: ...
        def stats(self) -> dict[str, Any]: ...
        def fit(self, uuid: str) -> dict[str, Any] | None: ...

log = logging.getLogger("moi.web")

HERE = Path(__file__).parent
#: a tick of the live stream every this many s (elapsed time, new samples)
TICK = 0.25
#: the largest history page asked for (its offset must stay an SQLite integer; no store has so many)
MAX_PAGE = 10**9
#: the latest parts an SPC page charts at most
SPC_POINTS = 500
#: the control charts the SPC page draws
CHARTS = ("auto", "I-MR", "Xbar-R", "Xbar-S")
#: keys whose values the set-up page never shows
SECRET_WORDS = ("password", "token", "secret")


class Refused(web.HTTPException):
    """A 4xx with a message (rendered as a page or as JSON by the error middleware)."""

    def __init__(self, status: int, message: str) -> None:
        self.status_code = status
        super().__init__(text=message)
        self.message = message


def _name(v: Any) -> Any:
    return v.get("name") if isinstance(v, Mapping) else v


def mask(obj: Any) -> Any:
    """``obj`` with the value of every key that names a secret replaced by ***."""
    if isinstance(obj, Mapping):
        return {k: ("***" if any(w in str(k).lower() for w in SECRET_WORDS) and v and not str(k).endswith("_file")
                    else mask(v)) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [mask(x) for x in obj]
    return obj


def _own_names(extra: tuple[str, ...]) -> frozenset[str]:
    """The host names this appliance answers for: localhost, its own names, and ``extra``."""
    import socket

    names = {"localhost", socket.gethostname(), socket.getfqdn()}
    names |= {n.split(".")[0] + ".local" for n in list(names) if n}
    return frozenset(n.lower().rstrip(".") for n in names | set(extra) if n)


def _is_ip(name: str) -> bool:
    import ipaddress

    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


async def _form(request: web.Request) -> Mapping[str, Any]:
    """The request's form fields; a body that does not parse (a multipart body cut short) is a 400."""
    try:
        return await request.post()
    except ValueError as exc:  # aiohttp's form and multipart readers say what was wrong with a ValueError
        raise Refused(400, f"malformed form body: {exc}") from None


def _wants_json(request: web.Request) -> bool:
    return request.path.startswith("/api/") or "application/json" in request.headers.get("Accept", "")


class Views:
    def __init__(self, server: "WebServer") -> None:
        self.server = server
        self.app = server.appliance
        self.live = Live(server.appliance)
        self.env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(HERE / "templates")),
                                      autoescape=jinja2.select_autoescape(["html"]), trim_blocks=True,
                                      lstrip_blocks=True)
        self.env.filters.update(fmt=Q.number, name=_name, inertia=Q.inertia, iso=Q.iso, when=self.when,
                                plain=Q.plain_text)
        self._names = _own_names(server.settings.server_names)
        self.capture_first = CaptureFirst(lambda: sensor_is_read(self.app))
        # file names carry a hash of the content: a browser never keeps a stale script after an update
        stamps = {f.name: hashlib.sha256(f.read_bytes()).hexdigest()[:10] for f in (HERE / "static").iterdir()}
        self.env.globals.update(version=__version__, PART_ID_LENGTH=PART_ID_LENGTH, allowed=allowed, STATE_WORDS=STATE_WORDS, VERDICT_WORDS=Q.VERDICT_WORDS,
                                states_json=json.dumps(vocabulary(), separators=(",", ":")),
                                static_url=lambda name: f"/static/{name}?v={stamps.get(name, '')}")

    # --- application ------------------------------------------------------------------------
    def application(self) -> web.Application:
        app = web.Application(middlewares=[self._errors, self._host_check, self.capture_first.middleware], client_max_size=64 * 1024)
        r = app.router
        r.add_get("/", self.home)
        r.add_get("/home/summary", self.home_summary)
        r.add_get("/spc", self.spc)
        r.add_get("/events", self.events)
        r.add_get("/api/state", self.api_state)
        r.add_post("/login", self.login)
        r.add_post("/logout", self.logout)
        r.add_post("/api/measure", self.measure)
        r.add_post("/api/abort", self.abort)
        r.add_post("/api/part", self.part)
        r.add_get("/history", self.history)
        r.add_get("/history/export.{fmt}", self.export)
        r.add_get("/results/{key}", self.result)
        r.add_get("/results/{key}/plot.png", self.plot)
        r.add_get("/results/{key}/trace.csv", self.trace_csv)
        r.add_get("/results/{key}/result.json", self.result_json)
        r.add_get("/results/{key}/fit.json", self.fit_json)
        r.add_get("/results/{key}/report", self.report)
        r.add_get("/results/{key}/report.pdf", self.report_pdf)
        r.add_get("/set", self.tensor_set)
        r.add_get("/api/set", self.api_set)
        r.add_post("/api/set/{action}", self.set_action)
        r.add_get("/setup", self.setup)
        r.add_get("/recipes", self.recipes)
        r.add_post("/recipes", self.recipes_change)
        r.add_get("/calibration", self.calibration)
        r.add_get("/users", self.users)
        r.add_post("/users", self.users_change)
        r.add_get("/api/health", self.api_health)
        r.add_get("/api/angle", self.api_angle)
        r.add_get("/setup/snapshot.png", self.snapshot)
        r.add_post("/setup/roi", self.camera_roi)
        r.add_static("/static/", HERE / "static")
        return app

    @web.middleware
    async def _errors(self, request: web.Request, handler):
        try:
            resp = await handler(request)
        except web.HTTPException as exc:
            if exc.status_code < 400:
                raise
            message = getattr(exc, "message", None) or exc.reason
            if exc.status_code == 404 and not isinstance(exc, Refused):
                message = f"no page {request.path!r} on this appliance"
            elif exc.status_code == 405:
                message = f"{request.method} is not allowed on {request.path}"
            elif exc.status_code == 413:
                message = "request body too large"
            return self._error(request, exc.status_code, message)
        except (asyncio.CancelledError, ConnectionResetError):
            raise
        except StoreDamaged as exc:  # the file's damage, not this server's bug: said, and seen in /api/health
            log.error("web request %s %s: %s", request.method, request.path[:200], exc)
            return self._error(request, 503, str(exc))
        except Exception as exc:
            log.exception("web request %s %s failed", request.method, request.path)
            return self._error(request, 500, f"internal error ({type(exc).__name__}); the appliance log has details")
        return resp

    @web.middleware
    async def _host_check(self, request: web.Request, handler):
        """Only requests that name this appliance: a page on another site whose name was made to point here
        (DNS rebinding) names its own host, and would otherwise read the results from a LAN browser."""
        host = (request.host or "").rsplit(":", 1)[0] if not (request.host or "").endswith("]") else request.host
        name = host.strip("[]").lower().rstrip(".")
        if name not in self._names and not _is_ip(name):
            raise Refused(421, f"this appliance does not answer for the host {host[:64]!r}; add it to [web] "
                               "server_names")
        return await handler(request)

    def _error(self, request: web.Request, status: int, message: str) -> web.Response:
        if _wants_json(request):
            return web.json_response({"error": message, "status": status}, status=status)
        return self._page(request, "error.html", status=status, message=message, code=status)

    def _page(self, request: web.Request, template: str, status: int = 200, **ctx: Any) -> web.Response:
        session = self.server.guard.session(request.cookies.get(COOKIE))
        # before a login, the login form's CSRF value, also in a SameSite=Strict cookie: another site's form
        # can carry neither (double submit)
        login_csrf = request.cookies.get(LOGIN_COOKIE) or secrets.token_urlsafe(18)
        ctx.setdefault("title", "")
        html = self.env.get_template(template).render(
            device_id=self.app.config.device_id, logged_in=session is not None,
            user=session.user if session else None, role=session.role if session else None,
            named_users=bool(self.server.guard.users),
            csrf=session.csrf if session else login_csrf, path=request.path_qs,
            simulated=self.app.config.simulated, **ctx)
        resp = web.Response(text=html, status=status, content_type="text/html",
                            headers={"Cache-Control": "no-store", "X-Content-Type-Options": "nosniff",
                                     "X-Frame-Options": "DENY", "Referrer-Policy": "same-origin"})
        if session is None:
            resp.set_cookie(LOGIN_COOKIE, login_csrf, httponly=True, samesite="Strict", path="/")
        return resp

    # --- home and live state ---------------------------------------------------------------------
    def unit(self, payload: Mapping[str, Any] | None = None) -> str:
        """The unit a result is shown in: its recipe's, else the set-up's."""
        return Q.display_unit(payload, self.server.settings.display_unit)

    def decimals(self, view: dict[str, Any]) -> dict[str, Any]:
        """``view`` (a ``Q.part_view``) with its recipe's ``display_decimals`` from the recipe directory (the
        published payload does not carry them: a page setting, not part of the result)."""
        recipe = view.get("recipe")
        book = getattr(self.app, "parts", None)
        if recipe and book is not None:
            found = next((r for r in book.book.recipes if r.name == recipe.get("name")), None)
            if found is not None and found.display_decimals is not None:
                view["recipe"] = {**recipe, "display_decimals": found.display_decimals}
        return view

    def summary(self) -> dict[str, Any]:
        """Home: the operator's panel (the part in hand: ready, in progress or its verdict; a calibration that
        refuses Measure), the shift's counters, the last parts and the calibration."""
        store = self.app.store
        now = dt.datetime.now().astimezone()
        shift = Q.shift_start(self.server.settings.shift_starts, now)
        parts = store.list(limit=12, parts_only=True, full=True) if store is not None else []
        last = store.latest("ok") if store is not None else None
        counts = store.verdict_counts(since=shift.timestamp()) if store is not None else {}
        live = extras(self.app)
        tracker = getattr(self.app, "parts", None)
        open_part = tracker.open_part if tracker is not None else None
        calibration = self.app.calibration_state()  # as the next result will be judged
        if calibration is not None and calibration.get("valid_until"):
            until = dt.date.fromisoformat(calibration["valid_until"])
            calibration = {**calibration, "days_left": (until - dt.datetime.now(dt.UTC).date()).days}
        tile = parts[0] if parts else None
        tile_view = self.decimals(Q.part_view(tile.payload, stored_result(tile.payload))) if tile else None
        tile_unit = self.unit(tile.payload if tile else None)
        part_id = live.get("part_id")
        recipe = live.get("recipe") or {}
        left = None
        if open_part and (open_part.get("part_id") != part_id or open_part.get("recipe") != recipe.get("name")):
            left, open_part = open_part, None  # another part's: the next release abandons it
        # the verdict is shown big only for the part that owns it: none in progress, and no other part ID set
        if open_part and open_part.get("done"):
            mode = "progress"
        elif tile is not None and (not part_id or part_id == tile.part_id):
            mode = "verdict"
        else:
            mode = "ready"
        why = Q.judgement(tile_view, tile_unit) if tile_view else None
        return {"tile": tile, "tile_view": tile_view, "tile_unit": tile_unit, "counts": counts,
                "tile_places": Q.places((tile_view or {}).get("recipe"), tile_unit, (tile_view or {}).get("U")),
                "why": why, "tile_band": Q.band(tile_view["recipe"], tile_view.get("value"), tile_view.get("U"),
                                                tile_unit) if tile_view else None,
                "mode": mode, "part_id": part_id, "recipe": live.get("recipe"),
                "repeat": bool(tile is not None and part_id and part_id == tile.part_id and mode == "verdict"),
                "shift": shift.strftime("%H:%M"), "strip": parts, "open_part": open_part, "left": left,
                "next_release": live.get("release_next"), "blocked": self.blocked(),
                "calibration": calibration, "last": last,
                "last_view": Q.part_view(last.payload, stored_result(last.payload)) if last else None,
                "last_unit": self.unit(last.payload if last else None)}

    def blocked(self) -> dict[str, str] | None:
        """Why the page refuses Measure, what to do and whom to call (a due calibration or a failed check
        standard: every part would be INVALID, and measuring again cannot change that); None when it may. The
        rule is the daemon's, every door's (``measure_block``); the words are the page's, with its local time."""
        block = self.app.measure_block()
        if block is None:
            return None
        calibration = block["calibration"]
        contact = self.server.settings.contact
        check = calibration.get("check_standard") or {}
        what, do = [], []
        if block["expired"]:
            what.append(f"The rig's calibration expired on {calibration.get('valid_until') or '–'}.")
            do.append("calibrate the rig")
        if check and not check.get("passed"):
            what.append(f"The check standard {check.get('name') or ''} failed (E_n = "
                        f"{Q.number(check.get('E_n'), '.2g')}, {self.when(check.get('finished_at'))}): the rig no "
                        "longer measures within its uncertainty.")
            do.append("find the cause and measure the check standard again")
        what_text = " ".join(what)
        do_text = (f"Do not measure parts: every result would be INVALID, and measuring again cannot change that. "
                   f"Call {contact} to {' and to '.join(do)}.")
        return {"what": what_text, "do": do_text}

    def when(self, ts: float | None) -> str:
        """A time as a person reads it on the pages: local, in [web] time_format."""
        return Q.local_time(ts, self.server.settings.time_format)

    async def _summary(self) -> dict[str, Any]:
        """``summary()`` with the running tensor set's orientation to mount (read on the main loop, which owns it)."""
        progress = await asyncio.wrap_future(self.app.call_soon(self.app.set_progress))
        s = self.summary()
        if progress is not None and progress.get("status") == "running" and progress.get("orientation"):
            o = progress["orientation"]
            s.update(mode="set", set=progress, drawing=axes_drawing(o["axis"], o.get("offset"), size=150))
        return s

    async def home(self, request: web.Request) -> web.Response:
        return self._page(request, "home.html", title="Home", state=self.live.snapshot(), s=await self._summary(),
                          recipes=self.app.parts.book.recipes)

    async def home_summary(self, request: web.Request) -> web.Response:
        """Home's operator panel, counters and last parts alone (the page fetches it after each result)."""
        html = self.env.get_template("summary.html").render(s=await self._summary())
        return web.Response(text=html, content_type="text/html", headers={"Cache-Control": "no-store"})

    async def api_state(self, request: web.Request) -> web.Response:
        return web.json_response(self.live.snapshot())

    async def events(self, request: web.Request) -> web.StreamResponse:
        """Server-sent events: ``state`` on every transition, ``tick`` every 0.25 s (progress, new samples); in a
        slot of its own (``streams``), for ``stream_lifetime`` at most, or until it yields its slot to another
        address's viewer or to a logged-in user's stream."""
        client = request.remote or "?"
        logged_in = self.server.guard.session(request.cookies.get(COOKIE)) is not None
        q = self.server.listen()
        slot = self.server.streams.take(client, logged_in, end=lambda: q.put_nowait(None))
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
        cursor: dict[str, Any] = {}
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
                    msg = self.live.snapshot(cursor)
                await resp.write(f"event: {msg['type']}\ndata: {json.dumps(msg, allow_nan=False, default=str)}\n\n"
                                 .encode())
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        return resp

    # --- login and actions ---------------------------------------------------------------------
    def _same_origin(self, request: web.Request) -> None:
        origin = request.headers.get("Origin")
        if origin and origin != "null" and urlsplit(origin).netloc != request.host:
            raise Refused(403, f"cross-site request from {origin!r} refused")

    def _next(self, request: web.Request, value: str | None) -> str:
        # only a path on this appliance: never an open redirect
        if value and value.startswith("/") and not value.startswith(("//", "/\\")) and "\\" not in value:
            return value
        return "/"

    async def login(self, request: web.Request) -> web.StreamResponse:
        self._same_origin(request)
        form = await _form(request)
        csrf, expected = str(form.get("csrf") or ""), request.cookies.get(LOGIN_COOKIE) or ""
        if not csrf or not expected or not hmac.compare_digest(csrf.encode(), expected.encode()):
            raise Refused(403, "missing or wrong CSRF token: reload the page and log in again")
        user, source = str(form.get("user") or "").strip(), request.remote or "?"
        guard = self.server.guard
        if user and (wait := guard.throttled(user, source)) > 0:
            status, why = 429, throttled_words(wait, source)
        elif (made := guard.login(str(form.get("token") or ""), user or None, source)) is None:
            await guard.wrong_token(source)  # a guess costs time
            status, why = 401, ("wrong user name or password" if user else
                                "wrong token: it is the first line of the appliance's web token file")
        else:
            sid, _ = made
            resp = web.HTTPSeeOther(self._next(request, str(form.get("next") or "")))
            resp.set_cookie(COOKIE, sid, max_age=int(SESSION_LIFETIME), httponly=True, samesite="Strict", path="/")
            raise resp
        if _wants_json(request):
            raise Refused(status, why)
        # the form again, with what was typed (not the password) and the error beside it
        page = self._page(request, "login.html", status=status, title="Log in", login_error=why,
                          login_user=user[:64], login_next=self._next(request, str(form.get("next") or "")))
        if status == 429:
            page.headers["Retry-After"] = str(math.ceil(wait))
        return page

    async def logout(self, request: web.Request) -> web.StreamResponse:
        self._same_origin(request)
        form = await _form(request)
        await self._authorise(request, form)
        self.server.guard.logout(request.cookies.get(COOKIE))
        resp = web.HTTPSeeOther("/")
        resp.del_cookie(COOKIE, path="/")
        raise resp

    async def _authorise(self, request: web.Request, form: Mapping[str, Any], action: str | None = None) -> str:
        """Refused unless the request may act (and its role may do ``action``); the source its commands are
        recorded with: "web", or "web:<name>" for a named user."""
        self._same_origin(request)
        bearer = None
        auth = request.headers.get("Authorization")
        if auth is not None:
            kind, _, value = auth.partition(" ")
            if kind.lower() != "bearer" or not value.strip():
                raise Refused(401, "Authorization must be 'Bearer <token>'")
            bearer = value.strip()
        why = self.server.guard.authorise(cookie=request.cookies.get(COOKIE), bearer=bearer,
                                          csrf=request.headers.get(CSRF_HEADER) or str(form.get("csrf") or ""))
        if why is not None:
            if bearer is not None:
                await self.server.guard.wrong_token(request.remote)  # a guess costs time
            raise Refused(*why)
        name, role = self.server.guard.who(cookie=request.cookies.get(COOKIE), bearer=bearer)
        if action is not None and not allowed(role, action):
            need = {"recipe": "change the recipe", "acknowledge": "acknowledge a fault",
                    "camera": "set the camera's region of interest"}.get(action, action)
            raise Refused(403, f"{name or 'this login'} ({role}) may not {need}: log in as a quality engineer "
                               "or an admin")
        return f"web:{name}" if name else "web"

    async def _action(self, request: web.Request, name: str) -> web.Response:
        form = await _form(request) if request.content_type in ("application/x-www-form-urlencoded",
                                                                 "multipart/form-data") else {}
        state = self.app.live_status().state
        source = await self._authorise(request, form, "acknowledge" if name == V.ABORT and state == "FAULT" else name)
        seq = self.app.sequencer
        if name == V.TRIGGER:
            blocked = self.blocked()  # said at once; the daemon refuses it too, as at every door
            if blocked is not None:
                raise Refused(409, f"{blocked['what']} {blocked['do']}")
        if name == V.TRIGGER and seq is not None and seq.busy:
            # said, not queued and silently dropped: the sequencer takes no trigger while it measures
            raise Refused(409, f"a measurement is already running ({state}): Measure again when it is IDLE")
        self.app.command(name, source)
        log.info("%s: %s requested (state %s)", source, name, state)
        if "text/html" in request.headers.get("Accept", "") and form:
            raise web.HTTPSeeOther("/")
        return web.json_response({"accepted": True, "command": name, "state": state}, status=202)

    async def measure(self, request: web.Request) -> web.Response:
        return await self._action(request, V.TRIGGER)

    async def abort(self, request: web.Request) -> web.Response:
        return await self._action(request, V.ABORT)

    async def part(self, request: web.Request) -> web.Response:
        """Select the recipe (name or number; 0 deselects) and/or set the part ID of the next measurements."""
        from measurement.errors import InvalidInput
        from service.parts.recipes import check_part_id

        form = await _form(request)
        recipe = str(form.get("recipe") or "").strip()
        source = await self._authorise(request, form, V.RECIPE if recipe else V.PART_ID)
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

    # --- the guided tensor set ---------------------------------------------------------------------
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
        return self._page(request, "tensor_set.html", title="Tensor set", progress=progress, latest=latest,
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
        form = await _form(request) if request.content_type in ("application/x-www-form-urlencoded",
                                                                 "multipart/form-data") else {}
        source = await self._authorise(request, form, "set")
        self.app.command(V.SET, source, {"action": action})
        log.info("web: set %s requested", action)
        if "text/html" in request.headers.get("Accept", "") and form:
            raise web.HTTPSeeOther("/set")
        return web.json_response({"accepted": True, "command": "set", "action": action}, status=202)

    # --- results ----------------------------------------------------------------------------------
    def _store(self) -> "Store":
        store = self.app.store
        assert store is not None  # the store is open before the page serves
        return store

    def _get(self, key: str, trace: bool = False) -> "Measurement":
        if not key or len(key) > 64 or not all(c.isalnum() or c == "-" for c in key):
            raise Refused(400, f"bad measurement id {key[:64]!r}: expected a UUID, a UUID prefix or a sequence number")
        store = self.app.store
        m = store.get(key, trace=trace) if store is not None else None
        if m is None:
            raise Refused(404, f"no measurement {key!r} (or the prefix is not unique)")
        return m

    async def result(self, request: web.Request) -> web.Response:
        m = self._get(request.match_info["key"])
        ctx = self._result_context(m)
        r = ctx["r"]
        steps = [s for s in r.steps if s.chosen] if r is not None else []
        return self._page(request, "result.html", title=f"Result {m.seq}", steps=steps,
                          flags=flag_words(m.flags), baseline=r.baseline if r is not None else None,
                          has_trace=self.app.config.store_trace, **ctx)

    def _result_context(self, m: "Measurement") -> dict[str, Any]:
        """What the result and report pages share: the stored measurement ``m``, its payload ``p`` (the envelope's
        part keys) and its result ``r``, typed (None: a failed measurement, or a row of an older result schema)."""
        p = m.payload or {}
        r = stored_result(p)
        unit = self.unit(p)
        view = self.decimals(Q.part_view(p, r))
        if view["kind"] == "release" and m.part_uuid and self.app.store is not None:
            # an earlier release of a part that has been judged since: where its verdict is
            later = self.app.store.list(limit=50, part_id=m.part_id, recipe=m.recipe, parts_only=True)
            done = next((r for r in later if r.part_uuid == m.part_uuid), None)
            view["part_done"] = {"uuid": done.uuid, "seq": done.seq, "verdict": done.part_verdict} if done else None
        return {"m": m, "p": p, "r": r, "unit": unit, "v": view, "band": Q.band(view["recipe"], view.get("value"),
                                                                           view.get("U"), unit),
                "places": Q.places(view["recipe"], unit, view.get("U") or view.get("std")),
                "why": Q.judgement(view, unit) if view["kind"] == "part" else None}

    async def fit_json(self, request: web.Request) -> web.Response:
        """The fit and its residual of one of the latest results (the live page draws them over the swing)."""
        key = request.match_info["key"]
        fit = self.server.fit(key)
        if fit is None:
            m = self._get(key)
            fit = self.server.fit(m.uuid)
        if fit is None:
            raise Refused(404, "only the latest results keep their fit for the live page; see the result's plot")
        return web.json_response(fit)

    async def report(self, request: web.Request) -> web.Response:
        """The quality record of one result: a page that prints on A4 (the PDF has the same content)."""
        m = self._get(request.match_info["key"])
        ctx = self._result_context(m)
        releases = Q.release_rows(ctx["v"], m.payload, ctx["r"], self._store().get)
        seen = sorted({f for r in releases for f in r["flags"] or ()} | set(m.flags))
        return self._page(request, "report.html", title=f"Report {m.seq}", releases=releases,
                          flags=flag_words(seen), **ctx)

    async def report_pdf(self, request: web.Request) -> web.Response:
        m = self._get(request.match_info["key"])
        fut = self.server.plot_future(m.uuid)
        if fut is not None:  # the evidence plot is being drawn: the report has it
            await asyncio.wrap_future(fut)
        decimals = self.decimals(Q.part_view(m.payload))["recipe"] or {}  # the recipe's: no result read
        body = await self._in_child(report_file, str(self.app.config.state_dir), m.uuid,
                                    self.server.settings.display_unit, self.server.settings.time_format,
                                    decimals.get("display_decimals"))
        return web.Response(body=body, content_type="application/pdf", headers={
            "Content-Disposition": f'attachment; filename="moi-{m.seq}-{m.uuid[:8]}-report.pdf"'})

    async def plot(self, request: web.Request) -> web.Response:

        m = self._get(request.match_info["key"])
        if m.status != "ok":
            raise Refused(404, f"measurement {m.seq} {m.status}: it has no result to plot")
        fut = self.server.plot_future(m.uuid)
        if fut is not None:
            await asyncio.wrap_future(fut)
        got = self._store().get_attachment(m.uuid, PLOT_NAME)
        if got is None:
            # stored without a plot (the page was off): identify the kept trace again, once, and keep the picture
            if not self._store().has_trace(m.uuid):
                raise Refused(404, f"measurement {m.seq} has no plot and no stored trace to draw one from")
            cfg = self.app.config
            job = (replot, str(cfg.state_dir), m.uuid, cfg.rig.to_dict(), cfg.identification, cfg.simulated,
                   self.server.settings.display_unit)
            await asyncio.wrap_future(self.server.submit_plot(m.uuid, lambda: self.server.child.call(*job)))
            got = self._store().get_attachment(m.uuid, PLOT_NAME)
        data, media = got
        return web.Response(body=data, content_type=media, headers={"Cache-Control": "max-age=86400, immutable"})

    async def _in_child(self, fn, *args) -> bytes:
        """``fn(*args)`` in the web page's child process (away from the capture's threads)."""
        try:
            return await self.server.child.run(fn, *args)
        except ChildBusy as exc:
            raise Refused(503, str(exc)) from None

    async def trace_csv(self, request: web.Request) -> web.Response:
        m = self._get(request.match_info["key"])
        if not self._store().has_trace(m.uuid):
            raise Refused(404, f"measurement {m.seq} was stored without its trace ([device] store_trace = false)")
        body = await self._in_child(trace_file, str(self.app.config.state_dir), m.uuid)
        return web.Response(body=body, content_type="text/csv", headers={
            "Content-Disposition": f'attachment; filename="moi-{m.seq}-{m.uuid[:8]}-trace.csv"'})

    async def result_json(self, request: web.Request) -> web.Response:
        m = self._get(request.match_info["key"])
        body = m.payload if m.payload is not None else {**m.summary(), "status": m.status}
        return web.Response(text=json.dumps(body, indent=2, ensure_ascii=False), content_type="application/json",
                            headers={"Content-Disposition": f'attachment; filename="moi-{m.seq}-{m.uuid[:8]}.json"'})

    # --- history -------------------------------------------------------------------------------------
    def _filters(self, request: web.Request) -> dict[str, Any]:
        q = request.query
        out: dict[str, Any] = {}

        def day(name: str) -> float | None:
            text = q.get(name, "").strip()
            if not text:
                return None
            try:
                d = dt.date.fromisoformat(text)
            except ValueError:
                raise Refused(400, f"{name}={text[:20]!r}: expected a date YYYY-MM-DD") from None
            return dt.datetime(d.year, d.month, d.day, tzinfo=dt.UTC).timestamp()

        out["since"] = day("since")
        until = day("until")
        out["until"] = until + 86400.0 if until is not None else None  # the whole last day
        status = q.get("status", "").strip()
        if status and status not in ("ok", "failed", "aborted"):
            raise Refused(400, f"status={status[:20]!r}: expected ok, failed or aborted")
        out["status"] = status or None
        flag = q.get("flag", "").strip()
        if len(flag) > 64:
            raise Refused(400, "flag: at most 64 characters")
        out["flag"] = flag or None
        for param, key in (("recipe", "recipe"), ("part", "part_id")):
            v = q.get(param, "").strip()
            if len(v) > 128:
                raise Refused(400, f"{param}: at most 128 characters")
            out[key] = v or None
        return out

    def _query_args(self, request: web.Request) -> dict[str, str]:
        return {k: request.query.get(k, "") for k in ("since", "until", "recipe", "part", "flag", "status")}

    async def history(self, request: web.Request) -> web.Response:
        filters = self._filters(request)
        size = self.server.settings.page_size
        try:
            page = int(request.query.get("page", "1"))
        except ValueError:
            raise Refused(400, f"page={request.query.get('page', '')[:20]!r}: expected a page number 1, 2, ...") from None
        if not 1 <= page <= MAX_PAGE:
            raise Refused(400, f"page: expected a page number 1, 2, ... (at most {MAX_PAGE})")
        rows, total = self._store().search(offset=(page - 1) * size, limit=size, **filters)
        pages = max(1, math.ceil(total / size))
        args = {k: v for k, v in self._query_args(request).items() if v}

        def link(n: int) -> str:
            return "/history?" + urlencode({**args, "page": n})

        export = urlencode(args)
        return self._page(request, "history.html", title="History", rows=rows, total=total, page=page, pages=pages,
                          unit=self.server.settings.display_unit, unit_of=self.unit,
                          q=self._query_args(request), link=link, export=export, flag_names=[(f, f"{f.replace('_', ' ')}: {w}" if w else f) for f, w in flag_words(sorted(FLAGS))],
                          recipes=self._store().recipes())

    async def export(self, request: web.Request) -> web.Response:
        fmt = request.match_info["fmt"]
        if fmt not in ("csv", "json", "dfq"):
            raise Refused(404, f"export format {fmt[:10]!r}: expected export.csv, export.json or export.dfq")
        filters = self._filters(request)
        if fmt == "dfq" and not filters["recipe"]:
            raise Refused(400, "a DFQ file holds one part type: give recipe=NAME")
        name = f"moi-{self.app.config.device_id}-{filters['recipe'] if fmt == 'dfq' else 'history'}.{fmt}"
        # the same files as `moi export` (oldest first)
        try:
            body = await self._in_child(export_file, str(self.app.config.state_dir), fmt, filters)
        except InputFileError as exc:  # no parts of that recipe
            raise Refused(404, str(exc)) from None
        if fmt == "csv":  # a byte-order mark: Excel on Windows reads the file as UTF-8 (kg·m², not kgÂ·mÂ²)
            body = "\ufeff".encode() + body
        media = {"json": "application/json", "csv": "text/csv", "dfq": "text/plain"}[fmt]
        return web.Response(body=body, content_type=media, charset="utf-8" if fmt != "dfq" else ENCODING,
                            headers={"Content-Disposition": content_disposition(name)})

    # --- SPC ---------------------------------------------------------------------------------------------------
    async def spc(self, request: web.Request) -> web.Response:
        """Control chart (I-MR, X̄–R or X̄–S) of one recipe's part values, Cp/Cpk with their confidence interval, rule
        violations marked and said in words."""
        from measurement.errors import InvalidInput
        from measurement.spc import SMALL_SAMPLE, capability_interval
        from service.parts.recipes import recipe_spc

        filters = self._filters(request)
        chart = request.query.get("chart", "auto")
        if chart not in CHARTS:
            raise Refused(400, f"chart={chart[:20]!r}: expected {', '.join(CHARTS)}")
        store = self.app.store
        recipes = store.recipes() if store is not None else []
        recipe = request.query.get("recipe", "").strip() or (recipes[-1] if recipes else "")
        if recipe and recipe not in recipes:
            raise Refused(404, f"no completed parts of recipe {recipe[:64]!r} in the store")
        result, note = None, None
        if recipe:
            loop = asyncio.get_running_loop()

            def compute(kind: str):
                return recipe_spc(store, recipe, since=filters["since"], until=filters["until"], chart=kind,
                                  limit=SPC_POINTS)
            try:
                result = await loop.run_in_executor(None, compute, chart)
            except InvalidInput as exc:  # subgroups of unequal size (a release excluded), or of one release
                note = (f"{chart} cannot be drawn from these parts ({exc}): every part needs the same number of "
                        "usable releases. Shown as I-MR of the part values instead.")
                result = await loop.run_in_executor(None, compute, "I-MR")
        unit = self.server.settings.display_unit
        book = getattr(self.app, "parts", None)
        if book is not None and recipe:
            with contextlib.suppress(InvalidInput):  # a recipe in the store no longer in the directory: the set-up's unit
                unit = book.book.find(recipe).display_unit or unit
        charts = capability = None
        if result is not None:
            names = [f"{p or '(no ID)'} {self.when(t)}" for p, t in zip(result.parts, result.finished)]
            charts = {w: Q.control_chart(result.summary, unit, width=w, names=names) for w in (720.0, 380.0)}
            s = result.summary
            values = s.n_points * s.subgroup
            capability = {"interval": capability_interval(s.cp, s.cpk, values), "n": values,
                          "small": values < SMALL_SAMPLE, "small_sample": SMALL_SAMPLE}
        q = {"since": request.query.get("since", ""), "until": request.query.get("until", ""), "chart": chart}
        checks, check_chart = self._checks(filters, unit)
        return self._page(request, "spc.html", title="SPC", recipes=recipes, recipe=recipe, spc=result,
                          chart=charts[720.0] if charts else None, narrow=charts[380.0] if charts else None,
                          note=note, capability=capability, charts=CHARTS, unit=unit, q=q,
                          checks=checks[-10:][::-1], check_chart=check_chart)

    def _checks(self, filters: Mapping[str, Any], unit: str) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
        """The check standard's history (`moi check-standard`) in the period, oldest first, and its control chart
        (individuals) from two checks on."""
        store = self.app.store
        checks = [c for c in reversed(store.check_standards(limit=SPC_POINTS) if store is not None else [])
                  if isinstance(c.get("value"), (int, float))
                  and (filters.get("since") is None or c["finished_at"] >= filters["since"])
                  and (filters.get("until") is None or c["finished_at"] < filters["until"])]
        check_chart = None
        if len(checks) >= 2:
            from measurement.spc import individuals

            summary = individuals([float(c["value"]) for c in checks])
            names = [f"{c.get('name') or 'check'} {self.when(c['finished_at'])}" for c in checks]
            check_chart = {kind: Q.control_chart(summary, unit, width=w, names=names)
                           for kind, w in (("wide", 720.0), ("narrow", 380.0))}
        return checks, check_chart

    async def calibration(self, request: web.Request) -> web.Response:
        """Each rig's calibration (date, due date, stiffness, the references it rests on), its history (every
        `moi calibrate`, newest first, a page at a time: ``service.sources.calibrations``) and the check
        standard's history with its control chart. ``?rig=N&before=BYTE``: rig N's older calibrations."""
        today = dt.datetime.now(dt.UTC).date()
        try:
            paged = int(request.query.get("rig", "-1"))
            before = int(request.query["before"]) if "before" in request.query else None
        except ValueError:
            raise Refused(400, "rig and before: expected whole numbers (the links of the history's pages)") from None
        if before is not None and before < 0:
            raise Refused(400, f"before={before}: expected a byte offset >= 0")
        rows = []
        for i, (name, rig, used_by, path) in enumerate(self._rigs()):
            cal = rig.calibration
            until = cal.valid_until if cal is not None else None
            # the file is read off the loop: a long history must not hold every other page up
            history = await asyncio.get_running_loop().run_in_executor(
                None, self._history, path, before if i == paged else None)
            # the store is the set-up's: its repeat releases tell the set-up's rig's scatter between releases
            repro = (await asyncio.get_running_loop().run_in_executor(None, self._reproducibility, cal)
                     if i == 0 else None)
            rows.append({"name": name, "used_by": used_by, "cal": cal, "until": until, "index": i, "repro": repro,
                         "days_left": (until - today).days if until is not None else None,
                         "due": cal is not None and cal.due(today), "stiffness": rig.stiffness,
                         "stiffness_std": rig.stiffness_std, "paged": i == paged and before is not None, **history})
        unit = self.server.settings.display_unit
        checks, check_chart = self._checks({}, unit)
        return self._page(request, "calibration.html", title="Calibration", rows=rows, unit=unit,
                          checks=checks[-20:][::-1], check_chart=check_chart, state=self.app.calibration_state(),
                          blocked=self.blocked())

    def _reproducibility(self, cal: Any) -> Reproducibility | None:
        """The set-up's rig's scatter of ω_n between releases, pooled from the store's repeat releases since its
        calibration (None without a store)."""
        store = self.app.store
        if store is None:
            return None
        since = (dt.datetime.combine(cal.date, dt.time(), dt.UTC).timestamp() if cal is not None else None)
        return rig_reproducibility(store, since)

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
        return {"history": [e | {"recorded": self.when(recorded_at(e))} for e in h.entries],
                "history_file": h.path.name, "history_damaged": h.damaged, "history_older": h.older}

    # --- recipes and calibration ---------------------------------------------------------------------------
    async def recipes(self, request: web.Request, status: int = 200, **ctx: Any) -> web.Response:
        """Every recipe as a quality engineer reads it before measuring: nominal, tolerance, limits, releases,
        decision rule and quality rules, in the recipe's unit and decimals; for the quality role, a form per
        recipe to edit them."""
        book = getattr(self.app, "parts", None)
        rows = []
        active = getattr(book, "recipe", None)
        for r in book.book.recipes if book is not None else ():
            d = {**r.to_dict(), "display_decimals": r.display_decimals}
            unit = Q.display_unit({"recipe": d}, self.server.settings.display_unit)
            rows.append({"r": d, "unit": unit, "places": Q.places(d, unit), "active": active is not None
                         and active.name == r.name, "rig": Path(r.rig_path).name if r.rig_path else None,
                         "file": recipe_values(r)})
        return self._page(request, "recipes.html", status=status, title="Recipes", rows=rows, editable=EDITABLE,
                          may_edit=self._may(request, "recipe"), **ctx)

    def _may(self, request: web.Request, action: str) -> bool:
        """Whether the logged-in session may do ``action`` (what a page offers it)."""
        session = self.server.guard.session(request.cookies.get(COOKIE))
        return session is not None and allowed(session.role, action)

    async def recipes_change(self, request: web.Request) -> web.StreamResponse:
        """Edit one recipe's [recipe] keys (quality role): checked as a recipe file is, written back in one
        step, the running recipes re-read, and one line per edit appended to the recipe audit log. A refusal is
        said on the page beside the recipe, with what was typed."""
        form = await _form(request)
        source = await self._authorise(request, form, "recipe")
        parts = getattr(self.app, "parts", None)
        if parts is None or parts.book.directory is None:
            raise Refused(409, "no recipe directory ([recipes] directory): there is no recipe to edit")
        try:
            recipe = parts.book.find(str(form.get("recipe") or ""))
        except RecipeError as exc:
            raise Refused(404, str(exc)) from None
        typed = {k.name: str(form[k.name]) for k in EDITABLE if k.name in form}
        loop = asyncio.get_running_loop()
        try:
            new, changes = await loop.run_in_executor(None, edit_recipe, recipe, typed)
        except (RecipeError, InputFileError) as exc:
            return await self.recipes(request, status=400, edit_error={"recipe": recipe.name, "error": str(exc),
                                                                       "typed": typed})
        if changes:
            # the book swapped whole, the other recipes as they were read: a part already open keeps its recipe
            book = RecipeBook(parts.book.directory, tuple(new if r.name == new.name else r
                                                          for r in parts.book.recipes))
            parts.book = book
            if parts.recipe is not None and parts.recipe.name == new.name:
                parts.recipe = book.find(new.name)
            line = await loop.run_in_executor(None, audit_recipe, self.app.config.state_dir / RECIPE_AUDIT_FILE,
                                              source, new, changes, dt.datetime.now(dt.UTC).isoformat(
                                                  timespec="seconds"))
            log.info("web: recipe edited: %s", line.strip())
        raise web.HTTPSeeOther(f"/recipes#recipe-{new.number}")

    # --- users (admin) ----------------------------------------------------------------------------
    def _admin(self, request: web.Request) -> None:
        if not self._may(request, "users"):
            raise Refused(403, "only an admin sees and changes the users: log in as one")

    async def users(self, request: web.Request, status: int = 200, **ctx: Any) -> web.Response:
        """The named users and their roles, with forms to add one, reset a password or change a role, disable or
        enable one, and remove one; how many wrong logins there were, in all and per user (each costs
        GUESS_DELAY, one at a time), and which user is locked out from which address and for how long
        (LOCKOUT_WRONG within LOCKOUT_WINDOW; an address past SOURCE_WRONG for every name)."""
        self._admin(request)
        guard = self.server.guard
        return self._page(request, "users.html", status=status, title="Users", users=list(guard.users.values()),
                          roles=ROLES, users_file=self.server.settings.users_file, wrong=guard.wrong_tokens, wrong_logins=guard.wrong_logins,
                          locked={n: guard.locked_for(n) for n in guard.users},
                          lockouts={k: left for k, left in guard.lockouts.locked().items() if k[1] in guard.users}
                          | {(a, ""): left for a, left in guard.source_lockouts.locked().items()},
                          source_wrong=SOURCE_WRONG, lockout_wrong=LOCKOUT_WRONG, lockout_window=LOCKOUT_WINDOW, lockout_time=LOCKOUT_TIME,
                          delay=GUESS_DELAY, max_name=MAX_USER_NAME, min_password=MIN_PASSWORD, **ctx)

    async def users_change(self, request: web.Request) -> web.StreamResponse:
        """add (or reset the password and role of) a user, or remove one; the users file is written and the
        change holds at once. A refusal is said on the page, with what was typed (not the password)."""
        form = await _form(request)
        await self._authorise(request, form, "users")
        path = self.server.settings.users_file
        if not path:
            raise Refused(409, "no [web] users_file: the token is the one login (set users_file to name users)")
        guard = self.server.guard
        users = dict(guard.users)
        action, role = str(form.get("action") or ""), str(form.get("role") or "operator")
        typed = {"typed_name": str(form.get("name") or "")[:MAX_USER_NAME], "typed_role": role}
        try:
            if action == "remove":
                name = check_user(str(form.get("name") or ""))
                if name not in users:
                    raise ValueError(f"no user {name!r}")
                if users[name].role == "admin" and sum(u.role == "admin" for u in users.values()) == 1:
                    raise ValueError("the last admin cannot be removed: add another admin first")
                del users[name]
            elif action in ("disable", "enable"):
                name = check_user(str(form.get("name") or ""))
                if name not in users:
                    raise ValueError(f"no user {name!r}")
                u = users[name]
                if action == "disable" and u.role == "admin" and sum(
                        v.role == "admin" and not v.disabled for v in users.values()) == 1 and not u.disabled:
                    raise ValueError("the last admin cannot be disabled: add another admin first")
                users[name] = User(u.name, u.role, u.password, action == "disable")
                if action == "enable":
                    guard.unlock(name)
            elif action == "add":
                name = check_user(str(form.get("name") or ""), str(form.get("password") or ""))
                if role not in ROLES:
                    raise ValueError(f"role: expected one of {', '.join(ROLES)}")
                users[name] = User(name, role, hash_password(str(form["password"])),
                                   name in users and users[name].disabled)  # enable is said, not implied
            else:
                raise ValueError("action: expected add, disable, enable or remove")
        except ValueError as exc:
            return await self.users(request, status=400, users_error=str(exc), **typed)
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, save_users, path, users)
        guard.users = users
        log.info("web: user %s %s by %s", name, {"add": "saved", "remove": "removed", "disable": "disabled", "enable": "enabled"}[action],
                 guard.who(cookie=request.cookies.get(COOKIE), bearer=None)[0] or "the token")
        raise web.HTTPSeeOther("/users")

    # --- set-up -----------------------------------------------------------------------------------------
    def health(self) -> dict[str, Any]:
        app = self.app
        cfg = app.config
        out: dict[str, Any] = {"software_version": __version__, "device_id": cfg.device_id,
                               "simulated": cfg.simulated, "state": app.live_status().state,
                               "loop_iterations": app.loop_iterations, "last_loop_error": app.last_loop_error}
        out.update(app.publisher_health())
        try:
            du = shutil.disk_usage(cfg.state_dir)
            out["disk"] = {"path": str(cfg.state_dir), "free_bytes": du.free, "total_bytes": du.total}
        except OSError:
            out["disk"] = None
        n = app.notifier
        ping = n.last_watchdog_ping
        out["watchdog"] = {"period_s": n.watchdog_period,
                           "last_ping_s_ago": (time.monotonic() - ping) if ping is not None else None}
        out["measurements_stored"] = app.store.count() if app.store is not None else None
        store = app.store
        out["store"] = {"damage": store.damage, "write_failure": store.write_failure} if store is not None else None
        return out

    async def api_health(self, request: web.Request) -> web.Response:
        return web.json_response(self.health())

    async def setup(self, request: web.Request, status: int = 200, **ctx: Any) -> web.Response:
        cfg = self.app.config
        sensor = self._sensor().LABEL
        devices = self.app.devices
        readable = devices is not None and getattr(devices.sensor, "read_position", None) is not None
        logged_in = self.server.guard.session(request.cookies.get(COOKIE)) is not None
        return self._page(request, "setup.html", status=status, title="Set-up", health=self.health(),
                          config=setup_words(mask(cfg.to_dict()), shown_paths=logged_in), sensor=sensor,
                          readable=readable, web=self.server.stats(), **self._camera_setup(request), **ctx)

    # --- the camera's region of interest (set-up page) ---------------------------------------------------
    def _camera_file(self) -> str | None:
        """The camera file the running camera was read from (None: the demo camera, or no camera)."""
        cfg = self.app.config
        if cfg.simulated:
            return cfg.simulation.camera
        hw = cfg.hardware
        return hw.camera.file if hw is not None and hw.camera is not None else None

    def _camera_setup(self, request: web.Request) -> dict[str, Any]:
        """What the set-up page shows of the camera's region of interest, and whether this login may set it."""
        config = self._camera()
        if config is None:
            return {}
        return {"roi": config.target.roi, "frame_size": (config.camera.width, config.camera.height),
                "camera_file": self._camera_file(),
                "may_set_roi": self._may(request, "camera") and self._camera_file() is not None}

    async def camera_roi(self, request: web.Request) -> web.StreamResponse:
        """Set the camera's region of interest (x, y, w, h px; all empty: the whole frame; quality role): checked
        as a camera file is, written to the camera file in one step, used from the next capture, and one line
        appended to the camera audit log. Refused while a measurement runs; a wrong value is said on the page
        with what was typed."""
        from service.config.camera import CAMERA_AUDIT_FILE, audit_camera, roi_from_typed, set_roi

        form = await _form(request)
        source = await self._authorise(request, form, "camera")
        config, path = self._camera(), self._camera_file()
        if config is None:
            raise Refused(404, "this appliance has no camera")
        if path is None:
            raise Refused(409, "the demo camera has no camera file: name one ([simulation] camera or "
                               "[hardware.camera] file) to set its region of interest")
        seq = self.app.sequencer
        if seq is not None and seq.busy:
            raise Refused(409, "a measurement is running: set the region when it is idle")
        typed = {k: str(form.get(k) or "")[:12] for k in ("x", "y", "w", "h")}
        loop = asyncio.get_running_loop()
        try:
            roi = roi_from_typed(typed, config.camera.width, config.camera.height)
            new, before = await loop.run_in_executor(None, set_roi, path, roi)
        except (VisionError, InputFileError) as exc:
            return await self.setup(request, status=400, roi_error=str(exc), roi_typed=typed)
        await asyncio.wrap_future(self.app.call_soon(lambda: self.app.use_camera(new)))
        line = await loop.run_in_executor(None, audit_camera, self.app.config.state_dir / CAMERA_AUDIT_FILE, source,
                                          path, before, roi, dt.datetime.now(dt.UTC).isoformat(timespec="seconds"))
        log.info("web: camera region of interest set: %s", line.strip())
        raise web.HTTPSeeOther("/setup#camera")

    def _sensor(self) -> Any:
        """The kind of angle sensor the appliance reads (``service.devices.sensors``)."""
        from service.devices.sensors import registry as sensors

        cfg = self.app.config
        return sensors.sensor(cfg.simulation.sensor if cfg.simulated or cfg.hardware is None else cfg.hardware.sensor)

    def _camera(self) -> Any:
        return self._sensor().camera_config(self.app.config)

    async def api_angle(self, request: web.Request) -> web.Response:
        """The angle now: the last sample while a measurement captures, else one read of the encoder."""
        seq = self.app.sequencer
        if seq is None or self.app.devices is None:
            raise Refused(503, "the appliance is not running its devices yet")
        if seq.busy:
            p = seq.progress(max(0, seq.progress(0)["next"] - 1))
            if p["angle"]:
                return web.json_response({"angle_rad": p["angle"][-1], "source": "capture"})
            raise Refused(409, "a measurement is starting; no sample yet")
        read = getattr(self.app.devices.sensor, "read_position", None)
        if read is None:
            raise Refused(404, "this angle sensor has no one-off read (a camera: use the snapshot)")
        loop = asyncio.get_running_loop()
        try:
            _, angle = await loop.run_in_executor(None, read)
        except Exception as exc:  # a sensor fault is the answer, not a server error
            raise Refused(503, f"angle read failed: {exc}") from None
        return web.json_response({"angle_rad": angle, "angle_deg": math.degrees(angle), "source": self._sensor().LABEL})

    async def snapshot(self, request: web.Request) -> web.Response:
        """One camera frame with the region of interest, the target found, the pivot and the angle axis (what
        `moi camera-check` draws: ``service.sources.marker_check``)."""
        config = self._camera()
        if config is None:
            raise Refused(404, "this appliance has no camera")
        seq, devices = self.app.sequencer, self.app.devices
        if seq is None or devices is None:
            raise Refused(503, "the appliance is not running its devices yet")
        camera = getattr(devices.sensor, "camera", None)
        if camera is None:
            raise Refused(404, "this camera sensor gives no single frames")

        def grab():  # on the main loop: never while a measurement reads the camera
            if seq.busy:
                raise Refused(409, "a measurement is running: the camera is busy; try again when it is idle")
            return camera.grab().image

        try:
            image = await asyncio.wrap_future(self.app.call_soon(grab))
            loop = asyncio.get_running_loop()
            png = await loop.run_in_executor(None, lambda: _annotated_png(image, config))
        except Refused:
            raise
        except Exception as exc:
            raise Refused(503, f"camera snapshot failed: {exc}") from None
        return web.Response(body=png, content_type="image/png", headers={"Cache-Control": "no-store"})


#: keys whose values name a file or a folder on the appliance: shown only to someone logged in
PATH_WORDS = ("file", "dir", "path", "port_name", "device")


def _words(v: Any) -> str:
    """A set-up value as a person reads it: yes/no, "not set", numbers without exponents, lists joined."""
    if v is None:
        return "not set"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, float)):
        return Q.number(v, ".7g")
    if isinstance(v, (list, tuple)):
        return ", ".join(_words(x) for x in v) or "none"
    return str(v)


def setup_words(config: Mapping[str, Any], *, shown_paths: bool) -> list[tuple[str, list[tuple[str, str]]]]:
    """The running configuration as (section, [(setting, value in words)]) for the set-up page: nested tables
    flattened to "table › key", secrets already masked; without a login, paths are not shown."""
    out: list[tuple[str, list[tuple[str, str]]]] = []

    def walk(prefix: str, d: Mapping[str, Any], rows: list[tuple[str, str]]) -> None:
        for k, v in d.items():
            label = f"{prefix} › {k}" if prefix else str(k)
            label = label.replace("_", " ")
            if isinstance(v, Mapping):
                walk(label, v, rows)
            elif isinstance(v, (list, tuple)) and v and all(isinstance(x, Mapping) for x in v):
                for i, x in enumerate(v, 1):
                    walk(f"{label} {i}", x, rows)
            elif not shown_paths and v and any(w in str(k).lower() for w in PATH_WORDS):
                rows.append((label, "(shown after logging in)"))
            else:
                rows.append((label, _words(v)))

    for section, d in config.items():
        rows: list[tuple[str, str]] = []
        if isinstance(d, Mapping):
            walk("", d, rows)
        else:
            rows.append((str(section), _words(d) if shown_paths or not any(w in str(section) for w in PATH_WORDS)
                         else "(shown after logging in)"))
        out.append((str(section).replace("_", " "), rows))
    return out


#: the view the tensor set's drawing is seen from: azimuth and elevation, degrees. An isometric view (45°, 35.3°)
#: would draw the axis [1, 1, 0] on top of z (both point at the viewer's vertical); from here no two of the
#: usual six orientations (x, y, z, xy, xz, yz) are drawn within 25° of each other
VIEW_AZIMUTH, VIEW_ELEVATION = 13.0, 28.0


def project(v: Any) -> tuple[float, float]:
    """A direction in the part's frame as seen on the drawing (right, up), from ``VIEW_AZIMUTH``/``VIEW_ELEVATION``."""
    a, e = math.radians(VIEW_AZIMUTH), math.radians(VIEW_ELEVATION)
    x, y, z = (float(t) for t in v)
    right = -math.sin(a) * x + math.cos(a) * y
    up = -math.sin(e) * math.cos(a) * x - math.sin(e) * math.sin(a) * y + math.cos(e) * z
    return right, up


def axes_drawing(axis: Any, offset: Any = None, size: int = 220) -> dict[str, Any]:
    """A small axonometric drawing of the part's frame and the swing axis (SVG coordinates, px): the part's
    x, y, z as arrows from its centre of mass, the swing axis as a line along ``axis`` through the point the
    offset gives (m from the centre of mass)."""
    half = size / 2
    scale = size * 0.32

    def at(v: Any) -> tuple[float, float]:
        r, u = project(v)
        return round(half + scale * r, 1), round(half - scale * u, 1)

    n = [float(t) for t in axis]
    length = math.sqrt(sum(t * t for t in n)) or 1.0
    n = [t / length for t in n]
    d = [float(t) for t in (offset or (0.0, 0.0, 0.0))]
    norm = math.sqrt(sum(t * t for t in d)) or 1.0
    # the swing axis passes the centre of mass at the offset (drawn at most half the frame's length away)
    p = [-t / norm * min(0.5, norm / 0.05) for t in d] if offset else [0.0, 0.0, 0.0]
    a, b = at([p[i] - 1.2 * n[i] for i in range(3)]), at([p[i] + 1.2 * n[i] for i in range(3)])
    return {"size": size, "origin": at((0, 0, 0)),
            "frame": [("x", at((1, 0, 0))), ("y", at((0, 1, 0))), ("z", at((0, 0, 1)))],
            "axis": (a, b), "axis_label": b}


def _annotated_png(frame, config) -> bytes:
    import cv2

    from service.sources.marker_check import check_image
    annotated, _report, _lines = check_image(frame, config)
    ok, buf = cv2.imencode(".png", annotated)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()
