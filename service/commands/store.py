"""`moi store check|salvage`: read a result store that may be damaged, and keep what can be read."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from service.errors import InputFileError

from ._common import add_store_arguments, find_store_dir


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=("check", "salvage"),
                   help="check: read every row and say what is damaged (exit 2 if anything is); "
                        "salvage: copy every readable row into a new store in --out")
    add_store_arguments(p)
    p.add_argument("--db", metavar="FILE", help="the database file itself (e.g. a results.db.damaged-… kept aside)")
    p.add_argument("--out", metavar="DIR", help="salvage: directory of the new store (must not hold one yet)")
    p.add_argument("--json", action="store_true", help="print the counts as JSON")


def run(args: argparse.Namespace) -> int:
    from service.persistence.salvage import check_store, salvage_store
    from service.persistence.store import DB_NAME

    if args.db:
        path = Path(args.db)
        if not path.is_file():
            raise InputFileError(f"{args.db}: no such file")
    else:
        path = find_store_dir(args) / DB_NAME
    if args.action == "check":
        health = check_store(path)
    else:
        if not args.out:
            raise InputFileError("salvage needs --out DIR: the new store is written there, the damaged one is left as it is")
        health = salvage_store(path, args.out)
    if args.json:
        print(json.dumps({"path": health.path, "ok": health.ok, "readable": health.readable, "lost": health.lost,
                          "problems": health.problems}, indent=2))
    else:
        print(health.summary())
        for problem in health.problems[:20]:
            print(f"  {problem}")
        if args.action == "salvage":
            print(f"salvaged into {Path(args.out) / DB_NAME}")
    return 0 if health.ok or args.action == "salvage" else 2
