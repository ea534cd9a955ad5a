"""`moi user add NAME --role ROLE --users-file FILE`: the web page's named users (operator, quality, admin);
`moi user remove NAME`, `moi user list`. Passwords are read from the terminal (or one line of standard input
with --password-stdin) and kept only as scrypt hashes; the file is written with mode 0600."""

from __future__ import annotations

import argparse
import getpass
import os
import sys
from pathlib import Path

from service.errors import InputFileError, StartupError
from service.names import name_problem
from service.publish.web.auth import ROLES, User, hash_password, read_users

#: shortest and longest password accepted, characters
MIN_PASSWORD, MAX_PASSWORD = 10, 1024


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=("add", "remove", "list"), help="add (or change) a user, remove one, list them")
    p.add_argument("name", nargs="?", metavar="NAME", help="the user's name (what results record)")
    p.add_argument("--users-file", required=True, metavar="FILE", help="the users file ([web] users_file)")
    p.add_argument("--role", choices=ROLES, default="operator", help="operator (measure), quality (also recipes "
                   "and fault acknowledge) or admin (default operator)")
    p.add_argument("--password-stdin", action="store_true", help="read the password from one line of stdin")


def _load(path: Path) -> dict[str, User]:
    if not path.exists():
        return {}
    try:
        return read_users(path)
    except StartupError as exc:
        raise InputFileError(str(exc)) from None


def _save(path: Path, users: dict[str, User]) -> None:
    import tomli_w

    text = "# moi web users: name, role (operator | quality | admin), scrypt password hash (moi user add)\n"
    text += tomli_w.dumps({"user": [{"name": u.name, "role": u.role, "password": u.password} for u in users.values()]})
    tmp = path.with_name(f".{path.name}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, path)


def run(args: argparse.Namespace) -> int:
    path = Path(args.users_file)
    if not path.parent.is_dir():
        raise InputFileError(f"--users-file {args.users_file!r}: the folder does not exist")
    users = _load(path)
    if args.action == "list":
        for u in users.values():
            print(f"{u.name}\t{u.role}")
        return 0
    name = (args.name or "").strip()
    if (problem := name_problem("user", name)) is not None:
        raise InputFileError(f"give the user's NAME: {problem}")
    if args.action == "remove":
        if users.pop(name, None) is None:
            raise InputFileError(f"no user {name!r} in {path}")
        _save(path, users)
        print(f"user {name} removed")
        return 0
    if args.password_stdin:
        password = sys.stdin.readline().rstrip("\n")
    else:
        password = getpass.getpass(f"password for {name}: ")
        if getpass.getpass("again: ") != password:
            raise InputFileError("the two passwords differ")
    if not MIN_PASSWORD <= len(password) <= MAX_PASSWORD:
        raise InputFileError(f"a password needs {MIN_PASSWORD} to {MAX_PASSWORD} characters")
    users[name] = User(name, args.role, hash_password(password))
    _save(path, users)
    print(f"user {name} ({args.role}) saved in {path}")
    return 0
