"""The users page (admin): the named users and their roles, the wrong logins and lockouts, and the forms that
add, disable, enable or remove a user."""

from __future__ import annotations

import asyncio
import logging
from typing import Any, Mapping

from aiohttp import web

from .auth import (
    COOKIE,
    GUESS_DELAY,
    LOCKOUT_TIME,
    LOCKOUT_WINDOW,
    LOCKOUT_WRONG,
    MAX_USER_NAME,
    MIN_PASSWORD,
    ROLES,
    SOURCE_WRONG,
    Guard,
    User,
    check_user,
    hash_password,
    save_users,
)
from .pages import Family, Refused, read_form

log = logging.getLogger("moi.web")

#: what each action did, in the log
DONE = {"add": "saved", "remove": "removed", "disable": "disabled", "enable": "enabled"}


def _known(users: Mapping[str, User], form: Mapping[str, Any]) -> str:
    name = check_user(str(form.get("name") or ""))
    if name not in users:
        raise ValueError(f"no user {name!r}")
    return name


def _change(users: dict[str, User], action: str, form: Mapping[str, Any], guard: Guard) -> str:
    """Apply ``action`` to ``users`` in place; the user's name (ValueError: what was wrong)."""
    admins = [u for u in users.values() if u.role == "admin"]
    if action == "remove":
        name = _known(users, form)
        if users[name].role == "admin" and len(admins) == 1:
            raise ValueError("the last admin cannot be removed: add another admin first")
        del users[name]
    elif action in ("disable", "enable"):
        name = _known(users, form)
        u = users[name]
        if action == "disable" and u.role == "admin" and sum(not v.disabled for v in admins) == 1 and not u.disabled:
            raise ValueError("the last admin cannot be disabled: add another admin first")
        users[name] = User(u.name, u.role, u.password, action == "disable")
        if action == "enable":
            guard.unlock(name)
    elif action == "add":
        name = check_user(str(form.get("name") or ""), str(form.get("password") or ""))
        role = str(form.get("role") or "operator")
        if role not in ROLES:
            raise ValueError(f"role: expected one of {', '.join(ROLES)}")
        users[name] = User(name, role, hash_password(str(form["password"])),
                           name in users and users[name].disabled)  # enable is said, not implied
    else:
        raise ValueError("action: expected add, disable, enable or remove")
    return name


class UserPages(Family):
    """``/users``, shown and changed (admin only)."""

    def _admin(self, request: web.Request) -> None:
        if not self.pages.may(request, "users"):
            raise Refused(403, "only an admin sees and changes the users: log in as one")

    async def users(self, request: web.Request, status: int = 200, **ctx: Any) -> web.Response:
        """The named users and their roles, with forms to add one, reset a password or change a role, disable or
        enable one, and remove one; how many wrong logins there were, in all and per user (each costs
        GUESS_DELAY, one at a time), and which user is locked out from which address and for how long
        (LOCKOUT_WRONG within LOCKOUT_WINDOW; an address past SOURCE_WRONG for every name)."""
        self._admin(request)
        guard = self.server.guard
        lockouts = ({k: left for k, left in guard.lockouts.locked().items() if k[1] in guard.users}
                    | {(a, ""): left for a, left in guard.source_lockouts.locked().items()})
        return self.pages.page(request, "users.html", status=status, title="Users", users=list(guard.users.values()),
                               roles=ROLES, users_file=self.server.settings.users_file, wrong=guard.wrong_tokens,
                               wrong_logins=guard.wrong_logins, locked={n: guard.locked_for(n) for n in guard.users},
                               lockouts=lockouts, source_wrong=SOURCE_WRONG, lockout_wrong=LOCKOUT_WRONG,
                               lockout_window=LOCKOUT_WINDOW, lockout_time=LOCKOUT_TIME, delay=GUESS_DELAY,
                               max_name=MAX_USER_NAME, min_password=MIN_PASSWORD, **ctx)

    async def users_change(self, request: web.Request) -> web.StreamResponse:
        """add (or reset the password and role of) a user, or remove one; the users file is written and the
        change holds at once. A refusal is said on the page, with what was typed (not the password)."""
        form = await read_form(request)
        await self.pages.authorise(request, form, "users")
        path = self.server.settings.users_file
        if not path:
            raise Refused(409, "no [web] users_file: the token is the one login (set users_file to name users)")
        guard = self.server.guard
        users = dict(guard.users)
        action = str(form.get("action") or "")
        try:
            name = _change(users, action, form, guard)
        except ValueError as exc:
            typed = {"typed_name": str(form.get("name") or "")[:MAX_USER_NAME],
                     "typed_role": str(form.get("role") or "operator")}
            return await self.users(request, status=400, users_error=str(exc), **typed)
        await asyncio.get_running_loop().run_in_executor(None, save_users, path, users)
        guard.users = users
        log.info("web: user %s %s by %s", name, DONE[action],
                 guard.who(cookie=request.cookies.get(COOKIE), bearer=None)[0] or "the token")
        raise web.HTTPSeeOther("/users")
