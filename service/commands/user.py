"""`moi user add NAME --role ROLE --users-file FILE`: the web page's named users (operator, quality, admin);
`moi user remove NAME`, `moi user list`. Passwords are read from the terminal (or one line of standard input
with --password-stdin) and kept only as scrypt hashes; the file is written with mode 0600."""

from __future__ import annotations

import argparse
import getpass
import sys
from pathlib import Path

from service.errors import InputFileError, StartupError
from service.publish.web.auth import ROLES, User, check_user, hash_password, read_users, save_users


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
    save_users(path, users)


def run(args: argparse.Namespace) -> int:
    path = Path(args.users_file)
    if not path.parent.is_dir():
        raise InputFileError(f"--users-file {args.users_file!r}: the folder does not exist")
    users = _load(path)
    if args.action == "list":
        for u in users.values():
            print(f"{u.name}\t{u.role}")
        return 0
    try:
        name = check_user(args.name or "")
    except ValueError as exc:
        raise InputFileError(f"give the user's NAME: {exc}") from None
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
    try:
        check_user(name, password)
    except ValueError as exc:
        raise InputFileError(str(exc)) from None
    users[name] = User(name, args.role, hash_password(password), name in users and users[name].disabled)  # enable is said, not implied
    _save(path, users)
    print(f"user {name} ({args.role}) saved in {path}")
    return 0
