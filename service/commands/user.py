"""`moi user add NAME --role ROLE --users-file FILE`: the web page's named users (operator, quality, admin);
`moi user change NAME` (a new password and/or role), `moi user remove NAME`, `moi user list`. Passwords are read
from the terminal (or one line of standard input with --password-stdin) and kept only as scrypt hashes; the file
is written with mode 0600. "add" refuses a name that exists (as the users page does: "change" changes one), and
every change is appended to the users audit log the page writes (``users-audit.log`` in the state directory)."""

from __future__ import annotations

import argparse
import datetime as dt
import getpass
import os
import sys
from pathlib import Path

from service.errors import InputFileError, StartupError
from service.publish.web.auth import (
    DONE,
    ROLES,
    USERS_AUDIT_FILE,
    User,
    admins_left,
    audit_users,
    check_user,
    has_admin,
    hash_password,
    read_users,
    save_users,
)

#: where systemd's StateDirectory=moi puts the state directory (the daemon's, where the page writes its audit log)
SYSTEM_STATE_DIR = Path("/var/lib/moi")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=("add", "change", "remove", "list"),
                   help="add a new user, change one's password or role, remove one, list them")
    p.add_argument("name", nargs="?", metavar="NAME", help="the user's name (what results record)")
    p.add_argument("--users-file", required=True, metavar="FILE", help="the users file ([web] users_file)")
    p.add_argument("--role", choices=ROLES, default=None, help="operator (measure), quality (also recipes "
                   "and fault acknowledge) or admin (add: default operator; change: the role kept unless given)")
    p.add_argument("--password-stdin", action="store_true", help="read the password from one line of stdin")
    p.add_argument("--keep-password", action="store_true", help="change: the role alone, the password kept")
    p.add_argument("--state-dir", metavar="DIR", help="the daemon's state directory, where users-audit.log is "
                   "appended to (default $STATE_DIRECTORY, else /var/lib/moi when it exists, else the users "
                   "file's folder)")


def _load(path: Path) -> dict[str, User]:
    if not path.exists():
        return {}
    try:
        return read_users(path)
    except StartupError as exc:
        raise InputFileError(str(exc)) from None


def audit_dir(args: argparse.Namespace, users_file: Path) -> Path:
    """The folder of the users audit log: --state-dir, $STATE_DIRECTORY, /var/lib/moi, else the users file's."""
    if args.state_dir:
        d = Path(args.state_dir)
        if not d.is_dir():
            raise InputFileError(f"--state-dir {args.state_dir!r}: the folder does not exist")
        return d
    env = os.environ.get("STATE_DIRECTORY")
    for d in ([Path(env.split(":")[0])] if env else []) + [SYSTEM_STATE_DIR]:
        if d.is_dir() and os.access(d, os.W_OK):
            return d
    return users_file.parent


def _password(args: argparse.Namespace, name: str) -> str:
    if args.password_stdin:
        return sys.stdin.readline().rstrip("\n")
    password = getpass.getpass(f"password for {name}: ")
    if getpass.getpass("again: ") != password:
        raise InputFileError("the two passwords differ")
    return password


def _changed(args: argparse.Namespace, users: dict[str, User], name: str, path: Path) -> User | None:
    """The user ``name`` after ``args.action`` (None: removed); refused with what to do instead."""
    old = users.get(name)
    if args.action == "remove":
        if old is None:
            raise InputFileError(f"no user {name!r} in {path}")
        return None
    if args.action == "add" and old is not None:
        raise InputFileError(f"user {name!r} exists in {path}: nothing changed; to give them a new password or "
                             f"role, use `moi user change {name}`")
    if args.action == "change" and old is None:
        raise InputFileError(f"no user {name!r} in {path}: to make one, use `moi user add {name}`")
    role = args.role or (old.role if old is not None else "operator")
    if old is not None and args.keep_password:
        return User(name, role, old.password, old.disabled)
    password = _password(args, name)
    try:
        check_user(name, password)
    except ValueError as exc:
        raise InputFileError(str(exc)) from None
    return User(name, role, hash_password(password), old is not None and old.disabled)  # enable is said, not implied


def run(args: argparse.Namespace) -> int:
    path = Path(args.users_file)
    if not path.parent.is_dir():
        raise InputFileError(f"--users-file {args.users_file!r}: the folder does not exist")
    users = _load(path)
    if args.action == "list":
        for u in users.values():
            print(f"{u.name}\t{u.role}{' (disabled)' if u.disabled else ''}")
        return 0
    try:
        name = check_user(args.name or "")
    except ValueError as exc:
        raise InputFileError(f"give the user's NAME: {exc}") from None
    if args.keep_password and args.action != "change":
        raise InputFileError("--keep-password goes with `moi user change` only")
    folder = audit_dir(args, path)
    before = users.get(name)
    after = _changed(args, users, name, path)
    had_admin = has_admin(users)
    if after is None:
        del users[name]
    else:
        users[name] = after
    try:
        admins_left(had_admin, users)
    except ValueError as exc:
        raise InputFileError(f"{exc} (`moi user add NAME --role admin`); nothing changed in {path}") from None
    save_users(path, users)
    try:
        who = f"cli:{getpass.getuser()}"
    except (OSError, KeyError):  # no login name in this environment (a container without USER)
        who = "cli"
    audit_users(folder / USERS_AUDIT_FILE, who, DONE[args.action], name, before, after,
                dt.datetime.now(dt.UTC).isoformat(timespec="seconds"))
    print(f"user {name} {DONE[args.action]}" + (f" ({after.role})" if after is not None else "") + f" in {path}; "
          f"audited in {folder / USERS_AUDIT_FILE}")
    return 0
