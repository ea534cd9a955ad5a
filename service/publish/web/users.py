"""The users page (admin): the named users and their roles, the wrong logins and lockouts, and the forms that
add, change, disable, enable or remove a user. Every change is appended to the users audit log; a form carries
the version of the users it was opened on, so a change made meanwhile by another admin is never overwritten."""

from __future__ import annotations

import asyncio
import datetime as dt
import hashlib
import logging
from typing import Any, Mapping

from aiohttp import web

from .auth import (
    DONE,
    GUESS_DELAY,
    LOCKOUT_TIME,
    LOCKOUT_WINDOW,
    LOCKOUT_WRONG,
    MAX_USER_NAME,
    MIN_PASSWORD,
    ROLES,
    SOURCE_WRONG,
    USERS_AUDIT_FILE,
    Guard,
    User,
    admins_left,
    audit_users,
    check_user,
    has_admin,
    hash_password,
    save_users,
)
from .pages import Family, Refused, read_form

log = logging.getLogger("moi.web")

def users_version(users: Mapping[str, User]) -> str:
    """A short digest of ``users`` as they are now: a form opened on another version was opened before a change."""
    text = "\n".join(f"{u.name}\t{u.role}\t{u.password}\t{u.disabled}" for u in users.values())
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def _known(users: Mapping[str, User], form: Mapping[str, Any]) -> str:
    name = check_user(str(form.get("name") or ""))
    if name not in users:
        raise ValueError(f"no user {name!r}")
    return name


def _set(users: dict[str, User], action: str, form: Mapping[str, Any]) -> str:
    """add a new user, or change an existing one's role (and password, when one is typed)."""
    password = str(form.get("password") or "")
    name = check_user(str(form.get("name") or ""), password if action == "add" or password else None)
    role = str(form.get("role") or "operator")
    if role not in ROLES:
        raise ValueError(f"role: expected one of {', '.join(ROLES)}")
    old = users.get(name)
    if action == "add" and old is not None:
        raise ValueError(f"user {name!r} exists: to reset their password or role, use \"change\"")
    if action == "change" and old is None:
        raise ValueError(f"no user {name!r}: to make one, use \"add\"")
    users[name] = User(name, role, hash_password(password) if password else old.password if old else "",
                       old is not None and old.disabled)  # enable is said, not implied
    return name


def _change(users: dict[str, User], action: str, form: Mapping[str, Any], guard: Guard) -> str:
    """Apply ``action`` to ``users`` in place; the user's name (ValueError: what was wrong)."""
    had_admin = has_admin(users)
    if action == "remove":
        name = _known(users, form)
        if str(form.get("confirm") or "") != name:
            raise ValueError(f"removing {name!r} needs its confirmation: tick \"yes, remove {name}\"")
        del users[name]
    elif action in ("disable", "enable"):
        name = _known(users, form)
        u = users[name]
        users[name] = User(u.name, u.role, u.password, action == "disable")
        if action == "enable":
            guard.unlock(name)
    elif action in ("add", "change"):
        name = _set(users, action, form)
    else:
        raise ValueError("action: expected add, change, disable, enable or remove")
    admins_left(had_admin, users)
    return name


class UserPages(Family):
    """``/users``, shown and changed (admin only)."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._changing = asyncio.Lock()  # one change at a time: read, check the version, write, audit

    def _admin(self, request: web.Request) -> None:
        if not self.pages.may(request, "users"):
            raise Refused(403, "only an admin sees and changes the users: log in as one")

    async def users(self, request: web.Request, status: int = 200, **ctx: Any) -> web.Response:
        """The named users and their roles, with forms to add one, change one's role or password, disable or
        enable one, and remove one (confirmed); how many wrong logins there were, in all and per user (each
        costs GUESS_DELAY, one at a time), and which user is locked out from which address and for how long
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
                               max_name=MAX_USER_NAME, min_password=MIN_PASSWORD,
                               users_version=users_version(guard.users), audit_file=USERS_AUDIT_FILE, **ctx)

    async def users_change(self, request: web.Request) -> web.StreamResponse:
        """add, change, disable, enable or remove a user; the users file is written, the change holds at once and
        is appended to the users audit log. A form opened before another change is refused (409) with the users
        as they are now; a refusal is said on the page, with what was typed (not the password)."""
        form = await read_form(request)
        who = await self.pages.authorise(request, form, "users")
        path = self.server.settings.users_file
        if not path:
            raise Refused(409, "no [web] users_file: the token is the one login (set users_file to name users)")
        guard = self.server.guard
        action = str(form.get("action") or "")
        typed = {"typed_name": str(form.get("name") or "")[:MAX_USER_NAME],
                 "typed_role": str(form.get("role") or "operator")}
        async with self._changing:
            # a script that sends no version read nothing it could have read stale
            if "version" in form and str(form["version"]) != users_version(guard.users):
                return await self.users(request, status=409, users_error="the users were changed since you opened "
                                        "this page (by another admin?): nothing was changed; here they are now, "
                                        "do it again if it still holds", **typed)
            users = dict(guard.users)
            try:
                name = _change(users, action, form, guard)
            except ValueError as exc:
                return await self.users(request, status=400, users_error=str(exc), **typed)
            loop = asyncio.get_running_loop()
            await loop.run_in_executor(None, save_users, path, users)
            before = guard.users.get(name)
            guard.users = users
            line = await loop.run_in_executor(None, audit_users, self.app.config.state_dir / USERS_AUDIT_FILE, who,
                                              DONE[action], name, before, users.get(name),
                                              dt.datetime.now(dt.UTC).isoformat(timespec="seconds"))
        log.info("web: user changed: %s", line.strip())
        raise web.HTTPSeeOther("/users")
