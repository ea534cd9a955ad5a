"""The route table and the middlewares. Every bad request gets a 4xx with a sentence saying what was wrong; an
unexpected error is logged and answered 500 with its type, never with a traceback. The pages themselves are in
one module per page family, on the shared context of ``pages``."""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import socket
from typing import TYPE_CHECKING, Any

from aiohttp import web

from service.errors import StoreDamaged

from .calibration import CalibrationPages
from .grr import GrrPages
from .home import HomePages
from .pages import HERE, Pages, Refused
from .priority import CaptureFirst, sensor_is_read
from .recipes import RecipePages
from .results import ResultPages
from .session import SessionPages
from .set_up import SetUpPages
from .spc import SpcPages
from .type1 import Type1Pages
from .users import UserPages

if TYPE_CHECKING:  # pragma: no cover
    from .pages import WebServer

log = logging.getLogger("moi.web")


def _own_names(extra: tuple[str, ...]) -> frozenset[str]:
    """The host names this appliance answers for: localhost, its own names, and ``extra``."""
    names = {"localhost", socket.gethostname(), socket.getfqdn()}
    names |= {n.split(".")[0] + ".local" for n in list(names) if n}
    return frozenset(n.lower().rstrip(".") for n in names | set(extra) if n)


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


class Views:
    """The web application: the page families on one shared context, their routes, and the middlewares."""

    def __init__(self, server: WebServer) -> None:
        self.pages = Pages(server)
        self.live = self.pages.live
        self._names = _own_names(server.settings.server_names)
        self.capture_first = CaptureFirst(lambda: sensor_is_read(server.appliance))

    def application(self) -> web.Application:
        app = web.Application(middlewares=[self._errors, self._host_check, self.capture_first.middleware],
                              client_max_size=64 * 1024)
        p = self.pages
        home, session, results = HomePages(p), SessionPages(p), ResultPages(p)
        spc, calibration, recipes = SpcPages(p), CalibrationPages(p), RecipePages(p)
        users, setup, type1, grr = UserPages(p), SetUpPages(p), Type1Pages(p), GrrPages(p)
        r = app.router
        r.add_get("/", home.home)
        r.add_get("/home/summary", home.home_summary)
        r.add_get("/spc", spc.spc)
        r.add_get("/events", home.events)
        r.add_get("/api/state", home.api_state)
        r.add_post("/login", session.login)
        r.add_post("/logout", session.logout)
        r.add_post("/api/measure", home.measure)
        r.add_post("/api/abort", home.abort)
        r.add_post("/api/part", home.part)
        r.add_get("/history", results.history)
        r.add_get("/history/export.{fmt}", results.export)
        r.add_get("/results/{key}", results.result)
        r.add_get("/results/{key}/plot.png", results.plot)
        r.add_get("/results/{key}/trace.csv", results.trace_csv)
        r.add_get("/results/{key}/result.json", results.result_json)
        r.add_get("/results/{key}/fit.json", results.fit_json)
        r.add_get("/results/{key}/report", results.report)
        r.add_get("/results/{key}/report.pdf", results.report_pdf)
        r.add_get("/set", home.tensor_set)
        r.add_get("/api/set", home.api_set)
        r.add_post("/api/set/{action}", home.set_action)
        r.add_get("/type1", type1.type1)
        r.add_get("/type1/{uuid}", type1.study)
        r.add_get("/type1/{uuid}/report.pdf", type1.pdf)
        r.add_get("/api/type1", type1.api)
        r.add_post("/api/type1/start", type1.start)
        r.add_post("/api/type1/abort", type1.abort)
        r.add_get("/setup", setup.setup)
        r.add_get("/recipes", recipes.recipes)
        r.add_post("/recipes", recipes.recipes_change)
        r.add_get("/calibration", calibration.calibration)
        r.add_get("/grr", grr.grr)
        r.add_get("/grr/report.pdf", grr.grr_pdf)
        r.add_get("/calibration/banner", calibration.banner)
        r.add_get("/users", users.users)
        r.add_post("/users", users.users_change)
        r.add_get("/api/health", setup.api_health)
        r.add_get("/api/angle", setup.api_angle)
        r.add_get("/setup/snapshot.png", setup.snapshot)
        r.add_post("/setup/roi", setup.camera_roi)
        r.add_static("/static/", HERE / "static")
        return app

    @web.middleware
    async def _errors(self, request: web.Request, handler: Any) -> web.StreamResponse:
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
            return self.pages.error(request, exc.status_code, message)
        except (asyncio.CancelledError, ConnectionResetError):
            raise
        except StoreDamaged as exc:  # the file's damage, not this server's bug: said, and seen in /api/health
            log.error("web request %s %s: %s", request.method, request.path[:200], exc)
            return self.pages.error(request, 503, str(exc))
        except Exception as exc:
            log.exception("web request %s %s failed", request.method, request.path)
            return self.pages.error(request, 500, f"internal error ({type(exc).__name__}); the appliance log has "
                                                  "details")
        return resp

    @web.middleware
    async def _host_check(self, request: web.Request, handler: Any) -> web.StreamResponse:
        """Only requests that name this appliance: a page on another site whose name was made to point here
        (DNS rebinding) names its own host, and would otherwise read the results from a LAN browser."""
        host = (request.host or "").rsplit(":", 1)[0] if not (request.host or "").endswith("]") else request.host
        name = host.strip("[]").lower().rstrip(".")
        if name not in self._names and not _is_ip(name):
            raise Refused(421, f"this appliance does not answer for the host {host[:64]!r}; add it to [web] "
                               "server_names")
        return await handler(request)
