"""Logging in and out: the login form's double-submit CSRF check, the throttle of wrong guesses, the session
cookie."""

from __future__ import annotations

import hmac
import math
import time

from aiohttp import web

from .auth import COOKIE, LOGIN_COOKIE, SESSION_LIFETIME, throttled_words
from .pages import Family, Refused, read_form, same_origin, wants_json


def _next(value: str | None) -> str:
    # only a path on this appliance: never an open redirect
    if value and value.startswith("/") and not value.startswith(("//", "/\\")) and "\\" not in value:
        return value
    return "/"


class SessionPages(Family):
    """``/login`` and ``/logout``."""

    async def login(self, request: web.Request) -> web.StreamResponse:
        same_origin(request)
        form = await read_form(request)
        csrf, expected = str(form.get("csrf") or ""), request.cookies.get(LOGIN_COOKIE) or ""
        if not csrf or not expected or not hmac.compare_digest(csrf.encode(), expected.encode()):
            raise Refused(403, "missing or wrong CSRF token: reload the page and log in again")
        user, source = str(form.get("user") or "").strip(), request.remote or "?"
        guard = self.server.guard
        if user and (wait := guard.throttled(user, source)) > 0:
            status, why = 429, throttled_words(wait, source, self.pages.when(time.time() + wait))
        elif (made := guard.login(str(form.get("token") or ""), user or None, source)) is None:
            await guard.wrong_token(source)  # a guess costs time
            status, why = 401, ("wrong user name or password" if user else
                                "wrong token: it is the first line of the appliance's web token file")
            if user and guard.disabled(str(form.get("token") or ""), user):
                status, why = 403, f"the user {user} is disabled: ask an admin to enable it"
            if user and (wait := guard.throttled(user, source)) > 0:  # this wrong password locked the name out
                why += "; " + throttled_words(wait, source, self.pages.when(time.time() + wait))
        else:
            sid, _ = made
            resp = web.HTTPSeeOther(_next(str(form.get("next") or "")))
            resp.set_cookie(COOKIE, sid, max_age=int(SESSION_LIFETIME), httponly=True, samesite="Strict", path="/")
            raise resp
        if wants_json(request):
            raise Refused(status, why)
        # the form again, with what was typed (not the password) and the error beside it
        page = self.pages.page(request, "login.html", status=status, title="Log in", login_error=why,
                               login_user=user[:64], login_next=_next(str(form.get("next") or "")))
        if status == 429:
            page.headers["Retry-After"] = str(math.ceil(wait))
        return page

    async def logout(self, request: web.Request) -> web.StreamResponse:
        same_origin(request)
        form = await read_form(request)
        await self.pages.authorise(request, form)
        self.server.guard.logout(request.cookies.get(COOKIE))
        resp = web.HTTPSeeOther("/")
        resp.del_cookie(COOKIE, path="/")
        raise resp
