"""Who may act: the token file, login sessions and the cross-site request forgery guard.

Read-only pages are open. Every action that moves hardware or changes state
needs either

* a session cookie from ``POST /login`` with the token (HttpOnly, SameSite=Strict)
  **and** the session's CSRF token in the ``X-CSRF-Token`` header or the ``csrf``
  form field (synchronizer token: another site can make the browser send the
  cookie, but cannot read the page that holds the CSRF token), or
* ``Authorization: Bearer <token>`` (scripts; a browser never adds it by itself).

A request whose ``Origin`` names another site is refused whatever it carries.

Operators by name: with a users file (``[web] users_file``, made by ``moi user add``) a person logs in
with their name and password and acts in their role; each measurement they start records their name
(trigger ``web:<name>``). Roles, each with what the ones before it may do:

* ``operator``: Measure, Abort a running measurement, set the part ID, the tensor set's redo/skip/abort;
* ``quality``: also change the recipe, acknowledge a fault, set the camera's region of interest, start and abort a
  Type 1 gauge study and find the gauge studies in the page's menu (the quality engineer);
* ``admin``: everything (the appliance's token, for scripts and for the set-up, acts as admin).

Passwords are kept as scrypt hashes (RFC 7914, ``hashlib.scrypt``: memory-hard, salted per user),
compared in constant time. Without a users file the token is the one login, as admin.
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import hmac
import logging
import math
import os
import secrets
import stat
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from service.errors import StartupError
from service.names import NAMES, name_problem
from service.publish.lockout import Lockouts

log = logging.getLogger("moi.web")

COOKIE = "moi_session"
CSRF_HEADER = "X-CSRF-Token"
#: a login lasts this long, s
SESSION_LIFETIME = 12 * 3600.0
#: at most this many live sessions (the oldest is dropped)
MAX_SESSIONS = 64
#: the cookie that carries the login form's CSRF value until a session exists (double submit)
LOGIN_COOKIE = "moi_login"
#: shortest token accepted, characters (the one made on first start has 24)
MIN_TOKEN_LENGTH = 16
#: each wrong token costs this long, one at a time for the whole server, s: at most 1/GUESS_DELAY guesses
#: per second, however many connections ask
GUESS_DELAY = 0.5
#: at most one "wrong tokens" line per this many seconds, s
GUESS_LOG_INTERVAL = 60.0
#: a user name given this many wrong passwords from one address within LOCKOUT_WINDOW s is locked out for
#: LOCKOUT_TIME s from that address only (its right password refused there too, and the user told so; an
#: admin's "enable" lifts it): a guesser elsewhere never keeps the user out at their own device
LOCKOUT_WRONG, LOCKOUT_WINDOW, LOCKOUT_TIME = 5, 900.0, 900.0
#: an address that gave this many wrong passwords within LOCKOUT_WINDOW, whatever the names, has its named
#: logins locked out for LOCKOUT_TIME (a guesser going through the names); the token's login never is
SOURCE_WRONG = 20
#: the lockouts now with their end (Unix time), in the state directory: a restart does not lift them
LOCKOUT_FILE_NAME = "web-lockouts.json"


#: what each change of a user did, in the log and the users audit log (the page's and `moi user`'s)
DONE = {"add": "added", "change": "changed", "remove": "removed", "disable": "disabled", "enable": "enabled"}
#: the append-only log of user changes, in the state directory: the users page and `moi user` write it
USERS_AUDIT_FILE = "users-audit.log"


def throttled_words(seconds: float, source: str, until: str) -> str:
    """What a login refused by a lockout is told (not "wrong password": the password was not even tried);
    ``until``: when the lockout ends, as the pages write a time."""
    minutes = max(1, math.ceil(seconds / 60))
    return (f"locked out after too many wrong passwords: logins with this name from your address ({source}) are "
            f"paused until {until} ({minutes} more min), the right password too (it was not tried). Log in from another device, ask an "
            "admin to enable your user, or log in with the appliance's token (first line of its web token file)")


def read_token(path: str | os.PathLike, *, create: bool) -> str:
    """The token in ``path`` (first line, stripped). create: make the file with a random token (mode 0600)
    when it does not exist. A missing (create False), empty or unreadable file is a ``StartupError``."""
    p = Path(path)
    if create and not p.exists():
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(secrets.token_urlsafe(18) + "\n")
            log.info("web: made a new action token in %s", p)
        except FileExistsError:
            pass
        except OSError as exc:
            raise StartupError(f"[web] cannot create the token file {str(p)!r}: {exc.strerror}") from None
    try:
        token = p.read_text(encoding="utf-8").strip().splitlines()[0].strip() if p.stat().st_size else ""
    except FileNotFoundError:
        raise StartupError(f"[web] token_file {str(p)!r} does not exist; put the action password in it") from None
    except (OSError, UnicodeDecodeError, IndexError) as exc:
        raise StartupError(f"[web] cannot read the token file {str(p)!r}: {exc}") from None
    if len(token) < MIN_TOKEN_LENGTH:
        raise StartupError(f"[web] the token in {str(p)!r} is empty or shorter than {MIN_TOKEN_LENGTH} characters "
                           "(delete the file to get a random one)")
    try:
        mode = p.stat().st_mode
    except OSError:
        mode = 0
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        log.warning("web: the token file %s can be read by other users (mode %o); chmod 600 it", p,
                    stat.S_IMODE(mode))
    return token


#: roles, each allowed what the ones before it are
ROLES = ("operator", "quality", "admin")
#: the least role of each action; an action not named here needs an operator
LEAST_ROLE = {"recipe": "quality", "acknowledge": "quality", "camera": "quality", "gauge": "quality",
              "users": "admin"}
#: shortest and longest password accepted, characters
MIN_PASSWORD, MAX_PASSWORD = 10, 1024
#: longest user name, characters
MAX_USER_NAME = NAMES["user"].length


def check_user(name: str, password: str | None = None) -> str:
    """``name`` stripped, when it is a user name (the names table's rule for a user) and
    ``password`` (when given) has MIN_PASSWORD to MAX_PASSWORD characters; else ValueError saying what is wrong."""
    n = (name or "").strip()
    if (problem := name_problem("user", n)) is not None:
        raise ValueError(problem)
    if password is not None and not MIN_PASSWORD <= len(password) <= MAX_PASSWORD:
        raise ValueError(f"a password needs {MIN_PASSWORD} to {MAX_PASSWORD} characters")
    return n
#: scrypt cost (RFC 7914): N = 2^14, r = 8, p = 1 takes 16 MiB and some 50 ms on a Raspberry Pi 4
SCRYPT_N, SCRYPT_R, SCRYPT_P = 2**14, 8, 1


def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """``password`` as "scrypt$N$r$p$salt$hash" (base64) for a users file."""
    salt = salt if salt is not None else secrets.token_bytes(16)
    digest = hashlib.scrypt(password.encode("utf-8"), salt=salt, n=SCRYPT_N, r=SCRYPT_R, p=SCRYPT_P, dklen=32)
    b64 = base64.b64encode
    return f"scrypt${SCRYPT_N}${SCRYPT_R}${SCRYPT_P}${b64(salt).decode()}${b64(digest).decode()}"


def check_password(password: str, stored: str) -> bool:
    """True when ``password`` matches the stored hash (constant-time comparison)."""
    try:
        kind, n, r, p, salt, digest = stored.split("$")
        if kind != "scrypt":
            return False
        got = hashlib.scrypt(password.encode("utf-8"), salt=base64.b64decode(salt), n=int(n), r=int(r), p=int(p),
                             dklen=len(base64.b64decode(digest)), maxmem=256 * 1024 * 1024)
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, base64.b64decode(digest))


@dataclass(frozen=True)
class User:
    name: str
    role: str
    password: str  # the scrypt hash
    disabled: bool = False  # kept, but may not log in (its sessions end at once)


def allowed(role: str, action: str) -> bool:
    """Whether ``role`` may do ``action`` (see the module docstring)."""
    need = LEAST_ROLE.get(action, "operator")
    return role in ROLES and ROLES.index(role) >= ROLES.index(need)


def has_admin(users: Mapping[str, User]) -> bool:
    """Whether an enabled admin is among ``users``."""
    return any(u.role == "admin" and not u.disabled for u in users.values())


def admins_left(before: bool, users: Mapping[str, User]) -> None:
    """The rule the users page and ``moi user`` share: a change never leaves the file without an enabled admin
    that had one (``before``), so that users can still be managed by name (ValueError says what to do)."""
    if before and not has_admin(users):
        raise ValueError("the last enabled admin cannot be demoted, disabled or removed: make another admin first")


def read_users(path: str | os.PathLike) -> dict[str, User]:
    """The users of a users file ([[user]] name, role, password hash); StartupError saying what is wrong."""
    import tomllib

    p = Path(path)
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise StartupError(f"[web] users_file {str(p)!r} does not exist; make it with `moi user add`") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise StartupError(f"[web] cannot read the users file {str(p)!r}: {exc}") from None
    users: dict[str, User] = {}
    for i, u in enumerate(doc.get("user") or ()):
        name, role, pw = (u.get(k) if isinstance(u, dict) else None for k in ("name", "role", "password"))
        disabled = u.get("disabled", False) if isinstance(u, dict) else False
        if not isinstance(disabled, bool):
            raise StartupError(f"[web] users file {str(p)!r}: user {i + 1}: disabled must be true or false")
        if not (isinstance(name, str) and name.strip()) or role not in ROLES or not (isinstance(pw, str)
                                                                                    and pw.startswith("scrypt$")):
            raise StartupError(f"[web] users file {str(p)!r}: user {i + 1} needs name, role (one of "
                               f"{', '.join(ROLES)}) and a scrypt password hash (moi user add)")
        if (problem := name_problem("user", name)) is not None:
            raise StartupError(f"[web] users file {str(p)!r}: user {i + 1}: {problem}")
        if name in users:
            raise StartupError(f"[web] users file {str(p)!r}: user {name!r} twice")
        users[name] = User(name, role, pw, disabled)
    return users


def save_users(path: str | os.PathLike, users: dict[str, User]) -> None:
    """Write ``users`` to the users file ``path`` (mode 0600, replaced in one step: a reader never sees half)."""
    import tomli_w

    p = Path(path)
    text = "# moi web users: name, role (operator | quality | admin), scrypt password hash (moi user add)\n"
    text += tomli_w.dumps({"user": [{"name": u.name, "role": u.role, "password": u.password,
                                     **({"disabled": True} if u.disabled else {})} for u in users.values()]})
    tmp = p.with_name(f".{p.name}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, p)


@dataclass
class Session:
    csrf: str
    expires: float
    user: str | None = None  # None: logged in with the token
    role: str = "admin"


class Guard:
    """Sessions and checks for one token."""

    def __init__(self, token: str, clock=time.monotonic, users: dict[str, User] | None = None,
                 lockout_file: str | os.PathLike | None = None, wall=time.time) -> None:
        self._token = token
        self.users = users or {}
        self._dummy = hash_password(secrets.token_urlsafe(12)) if self.users else ""
        self._clock = clock
        self._sessions: dict[str, Session] = {}
        self._lock = threading.Lock()
        self._guessing: asyncio.Lock | None = None  # made on the web loop, at the first wrong token
        self.wrong_tokens = 0
        self.wrong_logins: dict[str, int] = {}  # wrong passwords per user name, since the start
        # by (address, name typed) and by address: a name that is no user is counted as one (names are not
        # told apart); no account is ever locked out for every address
        self.lockouts: Lockouts[tuple[str, str]] = Lockouts(LOCKOUT_WRONG, LOCKOUT_WINDOW, LOCKOUT_TIME, clock)
        self.source_lockouts: Lockouts[str] = Lockouts(SOURCE_WRONG, LOCKOUT_WINDOW, LOCKOUT_TIME, clock)
        self._wrong_since_log = 0
        self._guess_logged_at = -float("inf")
        self._lockout_file = Path(lockout_file) if lockout_file is not None else None
        self._wall = wall
        self._restore_lockouts()

    def _restore_lockouts(self) -> None:
        """The lockouts of before a restart, from the lockout file (a restart must not lift them); a file that
        cannot be read is said in the log and lifts nothing it did not hold."""
        if self._lockout_file is None or not self._lockout_file.exists():
            return
        import json

        try:
            doc = json.loads(self._lockout_file.read_text(encoding="utf-8"))
            now = self._wall()
            for source, name, until in doc.get("names", ()):
                self.lockouts.hold((str(source), str(name)), float(until) - now)
            for source, until in doc.get("sources", ()):
                self.source_lockouts.hold(str(source), float(until) - now)
        except (OSError, ValueError, TypeError, AttributeError) as exc:
            log.warning("web: cannot read the lockouts kept in %s (%s): lockouts of before the start are lost",
                        self._lockout_file, exc)

    def _save_lockouts(self) -> None:
        """Write the lockouts now with their wall-clock end (replaced in one step), for the next start."""
        if self._lockout_file is None:
            return
        import json

        now = self._wall()
        doc = {"names": [[s, n, now + left] for (s, n), left in self.lockouts.locked().items()],
               "sources": [[s, now + left] for s, left in self.source_lockouts.locked().items()]}
        tmp = self._lockout_file.with_name(f".{self._lockout_file.name}.tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(json.dumps(doc) + "\n")
            os.replace(tmp, self._lockout_file)
        except OSError as exc:  # the lockout holds in memory whatever the disk says
            log.warning("web: cannot keep the lockouts in %s: %s", self._lockout_file, exc.strerror or exc)

    async def wrong_token(self, peer: str | None) -> None:
        """A wrong token was given: wait ``GUESS_DELAY``, one wrong token at a time for the whole server (a
        guesser opening many connections waits in line), and say so in the log once a minute at most."""
        self.wrong_tokens += 1
        self._wrong_since_log += 1
        now = self._clock()
        if now - self._guess_logged_at >= GUESS_LOG_INTERVAL:
            log.warning("web: %d wrong token(s) since the last such line (the latest from %s)",
                        self._wrong_since_log, peer or "?")
            self._guess_logged_at, self._wrong_since_log = now, 0
        if self._guessing is None:
            self._guessing = asyncio.Lock()
        async with self._guessing:
            await asyncio.sleep(GUESS_DELAY)

    def token_ok(self, candidate: str | None) -> bool:
        return candidate is not None and candidate != "" and hmac.compare_digest(candidate.encode(), self._token.encode())

    def login(self, candidate: str | None, user: str | None = None,
              source: str = "?") -> tuple[str, Session] | None:
        """A new session (id, session) when ``candidate`` is the token (no ``user``) or ``user``'s password,
        else None. A named login from ``source`` (the client's address) while ``throttled`` is refused unchecked."""
        if user:
            user = user[:MAX_USER_NAME + 1]  # a longer name is no user's either: the lockouts keep no more of it
            if self.throttled(user, source) > 0:
                return None
            u = self.users.get(user)
            if u is None:
                check_password(candidate or "", self._dummy)  # as long as for a user: names are not told apart
                self._wrong_password(user, source)
                return None
            if not check_password(candidate or "", u.password):
                self._wrong_password(u.name, source)
                return None
            if u.disabled:
                return None
            who: tuple[str | None, str] = (u.name, u.role)
        elif self.token_ok(candidate):
            who = (None, "admin")
        else:
            return None
        sid = secrets.token_urlsafe(24)
        s = Session(csrf=secrets.token_urlsafe(24), expires=self._clock() + SESSION_LIFETIME, user=who[0],
                    role=who[1])
        with self._lock:
            self._prune()
            if len(self._sessions) >= MAX_SESSIONS:
                del self._sessions[min(self._sessions, key=lambda k: self._sessions[k].expires)]
            self._sessions[sid] = s
        return sid, s

    def disabled(self, candidate: str | None, user: str) -> bool:
        """Whether ``user`` is disabled and ``candidate`` is their password (who knows it is told why they are
        refused; nobody else learns that the user exists)."""
        u = self.users.get(user)
        return u is not None and u.disabled and check_password(candidate or "", u.password)

    def _wrong_password(self, name: str, source: str) -> None:
        if name in self.users:
            self.wrong_logins[name] = self.wrong_logins.get(name, 0) + 1
        locked = False
        if self.lockouts.failed((source, name)):
            log.warning("web: logins as %r from %s locked out for %.0f s after %d wrong passwords within %.0f s",
                        name, source, LOCKOUT_TIME, LOCKOUT_WRONG, LOCKOUT_WINDOW)
            locked = True
        if self.source_lockouts.failed(source):
            log.warning("web: named logins from %s locked out for %.0f s after %d wrong passwords within %.0f s",
                        source, LOCKOUT_TIME, SOURCE_WRONG, LOCKOUT_WINDOW)
            locked = True
        if locked:
            self._save_lockouts()

    def throttled(self, name: str, source: str) -> float:
        """How much longer logins as ``name`` from ``source`` are locked out, s (0: not locked)."""
        return max(self.lockouts.locked_for((source, name)), self.source_lockouts.locked_for(source))

    def locked_for(self, name: str) -> float:
        """How much longer ``name`` is locked out from some address, s (0: from none)."""
        return max((left for (_, n), left in self.lockouts.locked().items() if n == name), default=0.0)

    def unlock(self, name: str) -> None:
        """Lift ``name``'s lockouts from every address and forget its recent wrong passwords (an admin enabled
        the user)."""
        self.lockouts.lift(lambda key: key[1] == name)
        self._save_lockouts()

    def logout(self, sid: str | None) -> None:
        with self._lock:
            self._sessions.pop(sid or "", None)

    def session(self, sid: str | None) -> Session | None:
        if not sid:
            return None
        with self._lock:
            s = self._sessions.get(sid)
            if s is not None and (s.expires < self._clock() or not self._may_log_in(s.user)):
                del self._sessions[sid]
                return None
            return s

    def _may_log_in(self, user: str | None) -> bool:
        """A session's user still exists and is not disabled (the token's session has no user)."""
        if user is None:
            return True
        u = self.users.get(user)
        return u is not None and not u.disabled

    def _prune(self) -> None:
        now = self._clock()
        for k in [k for k, s in self._sessions.items() if s.expires < now]:
            del self._sessions[k]

    def who(self, *, cookie: str | None, bearer: str | None) -> tuple[str | None, str]:
        """(user name, role) of an authorised request: the bearer token acts as admin without a name."""
        if bearer is not None:
            return None, "admin"
        s = self.session(cookie)
        return (s.user, s.role) if s is not None else (None, "operator")

    def authorise(self, *, cookie: str | None, csrf: str | None, bearer: str | None) -> tuple[int, str] | None:
        """None when the request may act, else (HTTP status, why not): 401 without a valid login or token,
        403 with a login but without its CSRF token."""
        if bearer is not None:
            return None if self.token_ok(bearer) else (401, "wrong token in the Authorization header")
        s = self.session(cookie)
        if s is None:
            return 401, "log in first: this action needs the appliance's token"
        if not csrf or not hmac.compare_digest(csrf.encode(), s.csrf.encode()):
            return 403, "missing or wrong CSRF token: reload the page and try again"
        return None


def audit_users(log_path: str | Path, who: str, action: str, name: str, before: User | None, after: User | None,
                when: str) -> str:
    """Append one line to the users audit log (``when`` ISO time, who, action, user, role and state: before →
    after; a new password is said, never written) and return it; the log is only ever appended to."""
    def state(u: User | None) -> str:
        return "–" if u is None else f"{u.role}{' disabled' if u.disabled else ''}"
    pw = "; new password" if before is not None and after is not None and before.password != after.password else ""
    line = f"{when}\t{who}\t{action}\t{name}\t{state(before)} → {state(after)}{pw}\n"
    with open(log_path, "a", encoding="utf-8") as f:
        f.write(line)
    return line
