"""What every page shares: the refusal (a 4xx with a sentence), the form and query readers, the templates and
the page they render, the login check of every action, the store reads, the child process, the words of a time,
a unit and a blocked Measure. Each page family (``home``, ``session``, ``results``, ``spc``, ``calibration``,
``recipes``, ``users``, ``set_up``, ``type1``, ``grr``) is a small class holding the one ``Pages`` of the server."""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import secrets
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Protocol
from urllib.parse import urlsplit

import jinja2
from aiohttp import web

from service import __version__
from service.core import vocabulary as V
from service.parts import calibration as calibration_rule
from service.parts.recipes import PART_ID_LENGTH
from service.states import STATES, vocabulary

from .. import quality as Q
from ..budget import BUDGET_FOOTNOTE, budget_rows
from ..words import STATE_WORDS
from .auth import COOKIE, CSRF_HEADER, LOGIN_COOKIE, allowed
from .child import ChildBusy
from .live import Live

if TYPE_CHECKING:  # pragma: no cover
    import asyncio
    import concurrent.futures

    from service.persistence.store import Store
    from service.persistence.store import StoredMeasurement as Measurement
    from service.publish.port import ApplianceView

    from .auth import Guard
    from .child import ChildWork
    from .settings import WebSettings
    from .streams import StreamSlots

    class WebServer(Protocol):
        """What the pages use of the server that owns them (``server.WebServer``)."""

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

HERE = Path(__file__).parent
#: what a refusal of an action needs, in words
NEEDS = {"recipe": "change the recipe", "acknowledge": "acknowledge a fault",
         "camera": "set the camera's region of interest", "gauge": "start or abort a gauge study"}
#: the history's filters in the query string (the history, its export and the SPC page read them)
FILTERS = ("since", "until", "recipe", "part", "flag", "status")


class Refused(web.HTTPException):
    """A 4xx with a message (rendered as a page or as JSON by the error middleware)."""

    def __init__(self, status: int, message: str) -> None:
        self.status_code = status
        super().__init__(text=message)
        self.message = message


async def read_form(request: web.Request) -> Mapping[str, Any]:
    """The request's form fields; a body that does not parse (a multipart body cut short) is a 400."""
    try:
        return await request.post()
    except ValueError as exc:  # aiohttp's form and multipart readers say what was wrong with a ValueError
        raise Refused(400, f"malformed form body: {exc}") from None


async def action_form(request: web.Request) -> Mapping[str, Any]:
    """The form of an action a page's button posts; none from a client that posts JSON or nothing."""
    if request.content_type in ("application/x-www-form-urlencoded", "multipart/form-data"):
        return await read_form(request)
    return {}


def wants_json(request: web.Request) -> bool:
    return request.path.startswith("/api/") or "application/json" in request.headers.get("Accept", "")


def same_origin(request: web.Request) -> None:
    origin = request.headers.get("Origin")
    if origin and origin != "null" and urlsplit(origin).netloc != request.host:
        raise Refused(403, f"cross-site request from {origin!r} refused")


def _day(query: Mapping[str, str], name: str) -> float | None:
    text = query.get(name, "").strip()
    if not text:
        return None
    try:
        d = dt.date.fromisoformat(text)
    except ValueError:
        raise Refused(400, f"{name}={text[:20]!r}: expected a date YYYY-MM-DD") from None
    return dt.datetime(d.year, d.month, d.day, tzinfo=dt.UTC).timestamp()


def history_filters(request: web.Request) -> dict[str, Any]:
    """The store search's filters from the query string (a wrong one is a 400 saying what was expected)."""
    q = request.query
    out: dict[str, Any] = {"since": _day(q, "since")}
    until = _day(q, "until")
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


def query_args(request: web.Request) -> dict[str, str]:
    """The history's filters as typed (the form shows them again, the page links carry them)."""
    return {k: request.query.get(k, "") for k in FILTERS}


def _name(v: Any) -> Any:
    return v.get("name") if isinstance(v, Mapping) else v


def _environment(when: Any) -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(HERE / "templates")),
                             autoescape=jinja2.select_autoescape(["html"]), trim_blocks=True, lstrip_blocks=True)
    env.filters.update(fmt=Q.number, name=_name, inertia=Q.inertia, iso=Q.iso, when=when, plain=Q.plain_text,
                       reason=Q.reason, spread=Q.spread)
    # file names carry a hash of the content: a browser never keeps a stale script after an update
    stamps = {f.name: hashlib.sha256(f.read_bytes()).hexdigest()[:10] for f in (HERE / "static").iterdir()}
    env.globals.update(version=__version__, PART_ID_LENGTH=PART_ID_LENGTH, allowed=allowed, STATE_WORDS=STATE_WORDS,
                       VERDICT_WORDS=Q.VERDICT_WORDS, budget_rows=budget_rows, BUDGET_FOOTNOTE=BUDGET_FOOTNOTE,
                       states_json=json.dumps(vocabulary(), separators=(",", ":")),
                       BUSY_STATES=frozenset(name for name, info in STATES.items() if info.busy),
                       static_url=lambda name: f"/static/{name}?v={stamps.get(name, '')}")
    return env


class Pages:
    """The shared context of the page families: the server, the appliance, the templates, the live state."""

    def __init__(self, server: WebServer) -> None:
        self.server = server
        self.app = server.appliance
        self.live = Live(server.appliance)
        self.env = _environment(self.when)

    # --- templates ----------------------------------------------------------------------------------
    def page(self, request: web.Request, template: str, status: int = 200, **ctx: Any) -> web.Response:
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
            simulated=self.app.config.simulated, boot=self.live.boot, measure_block=self.blocked, **ctx)
        resp = web.Response(text=html, status=status, content_type="text/html",
                            headers={"Cache-Control": "no-store", "X-Content-Type-Options": "nosniff",
                                     "X-Frame-Options": "DENY", "Referrer-Policy": "same-origin"})
        if session is None:
            resp.set_cookie(LOGIN_COOKIE, login_csrf, httponly=True, samesite="Strict", path="/")
        return resp

    def error(self, request: web.Request, status: int, message: str) -> web.Response:
        if wants_json(request):
            return web.json_response({"error": message, "status": status}, status=status)
        return self.page(request, "error.html", status=status, message=message, code=status)

    # --- words --------------------------------------------------------------------------------------
    def when(self, ts: float | None) -> str:
        """A time as a person reads it on the pages: local, in [web] time_format."""
        return Q.local_time(ts, self.server.settings.time_format)

    def unit(self, payload: Mapping[str, Any] | None = None) -> str:
        """The unit a result is shown in: its recipe's, else the set-up's."""
        return Q.display_unit(payload, self.server.settings.display_unit)

    def places(self, payload: Mapping[str, Any] | None) -> int | str:
        """The decimals a result's value is written with on its page (its recipe's, in its unit), for a list of
        results: seven significant digits for a value without a recipe."""
        recipe = self.decimals({"recipe": (payload or {}).get("recipe")})["recipe"]
        return Q.places(recipe, self.unit(payload)) if recipe else ".7g"

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

    def recipe_display(self, name: str | None) -> tuple[str, dict[str, Any]]:
        """The unit a recipe's figures are shown in (its own, else the set-up's) and its ``display_decimals``
        (``{}`` without: from the tolerance), by its name in the recipe directory (a recipe no longer there:
        the set-up's unit)."""
        from measurement.errors import InvalidInput

        unit, shown = self.server.settings.display_unit, dict[str, Any]()
        book = getattr(self.app, "parts", None)
        if book is not None and name:
            try:
                found = book.book.find(name)
            except InvalidInput:
                return unit, shown
            unit = found.display_unit or unit
            if found.display_decimals is not None:
                shown = {"display_decimals": found.display_decimals}
        return unit, shown

    def blocked(self) -> dict[str, str] | None:
        """Why the page refuses Measure, what to do and whom to call (a due calibration or a failed check
        standard: every part would be INVALID, and measuring again cannot change that); None when it may. The
        rule is the daemon's, every door's (``measure_block``); the words are the page's, with its local time."""
        block = self.app.measure_block()
        if block is None:
            return None
        calibration = block["calibration"]
        check = calibration.get("check_standard") or {}
        what, do = [], []
        if block.get("uncalibrated"):
            words = calibration_rule.UNCALIBRATED
            what.append(f"{words[0].upper()}{words[1:]}, and this appliance's set-up requires one.")
            do.append("calibrate the rig")
        if block["expired"]:
            what.append(f"The rig's calibration expired on {calibration.get('valid_until') or '–'}.")
            do.append("calibrate the rig")
        if check and not check.get("passed"):
            what.append(f"The check standard {check.get('name') or ''} failed (E_n = "
                        f"{Q.number(check.get('E_n'), '.2g')}, {self.when(check.get('finished_at'))}): the rig no "
                        "longer measures within its uncertainty.")
            do.append("find the cause and measure the check standard again")
        do_text = (f"Do not measure parts: every result would be INVALID, and measuring again cannot change that. "
                   f"Call {self.server.settings.contact} to {' and to '.join(do)}.")
        return {"what": " ".join(what), "do": do_text}

    # --- the login check ----------------------------------------------------------------------------
    def logged_in(self, request: web.Request) -> bool:
        return self.server.guard.session(request.cookies.get(COOKIE)) is not None

    def may(self, request: web.Request, action: str) -> bool:
        """Whether the logged-in session may do ``action`` (what a page offers it)."""
        session = self.server.guard.session(request.cookies.get(COOKIE))
        return session is not None and allowed(session.role, action)

    async def authorise(self, request: web.Request, form: Mapping[str, Any], action: str | None = None) -> str:
        """Refused unless the request may act (and its role may do ``action``); the source its commands are
        recorded with: "web", or "web:<name>" for a named user."""
        same_origin(request)
        bearer = None
        auth = request.headers.get("Authorization")
        if auth is not None:
            kind, _, value = auth.partition(" ")
            if kind.lower() != "bearer" or not value.strip():
                raise Refused(401, "Authorization must be 'Bearer <token>'")
            bearer = value.strip()
        guard = self.server.guard
        why = guard.authorise(cookie=request.cookies.get(COOKIE), bearer=bearer,
                              csrf=request.headers.get(CSRF_HEADER) or str(form.get("csrf") or ""))
        if why is not None:
            if bearer is not None:
                await guard.wrong_token(request.remote)  # a guess costs time
            raise Refused(*why)
        name, role = guard.who(cookie=request.cookies.get(COOKIE), bearer=bearer)
        if action is not None and not allowed(role, action):
            raise Refused(403, f"{name or 'this login'} ({role}) may not {NEEDS.get(action, action)}: log in as a "
                               "quality engineer or an admin")
        return V.web_source(name)

    # --- the store and the child process ----------------------------------------------------------
    def store(self) -> Store:
        store = self.app.store
        assert store is not None  # the store is open before the page serves
        return store

    def measurement(self, key: str, trace: bool = False) -> Measurement:
        """The stored measurement ``key`` names (a UUID, a UUID prefix or a sequence number), or a 4xx."""
        if not key or len(key) > 64 or not all(c.isalnum() or c == "-" for c in key):
            raise Refused(400, f"bad measurement id {key[:64]!r}: expected a UUID, a UUID prefix or a sequence number")
        store = self.app.store
        m = store.get(key, trace=trace) if store is not None else None
        if m is None:
            raise Refused(404, f"no measurement {key!r} (or the prefix is not unique)")
        return m

    async def in_child(self, fn: Any, *args: Any) -> bytes:
        """``fn(*args)`` in the web page's child process (away from the capture's threads)."""
        try:
            return await self.server.child.run(fn, *args)
        except ChildBusy as exc:
            raise Refused(503, str(exc)) from None


class Family:
    """A page family: its handlers, on the pages' shared context."""

    def __init__(self, pages: Pages) -> None:
        self.pages = pages
        self.app = pages.app
        self.server = pages.server
