"""What `moi results` and `moi export` share: finding the result store."""

from __future__ import annotations

import argparse
import os
from datetime import UTC, datetime
from pathlib import Path

from service.errors import InputFileError, StoreError
from service.persistence.store import DB_NAME, Store

#: where systemd's StateDirectory=moi puts the store
SYSTEM_STATE_DIR = Path("/var/lib/moi")


def add_store_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--state-dir", metavar="DIR", help="directory of results.db")
    g.add_argument("--config", "-c", metavar="appliance.toml", help="take the state directory from this config")


def open_store(args: argparse.Namespace) -> Store:
    """The store named by --state-dir / --config, else $STATE_DIRECTORY, ./moi-state or /var/lib/moi."""
    d = find_store_dir(args)
    try:
        return Store(d, read_only=True)  # the reading commands never write (a read-only store opens)
    except StoreError as exc:
        raise InputFileError(str(exc)) from None


def find_store_dir(args: argparse.Namespace) -> Path:
    """The directory of the store named by --state-dir / --config, else $STATE_DIRECTORY, ./moi-state
    or /var/lib/moi (the first that holds one)."""
    if args.state_dir:
        candidates = [Path(args.state_dir)]
    elif args.config:
        from service.config.appliance import load_config  # only with --config: it loads the drivers' settings

        candidates = [load_config(args.config).state_dir]
    else:
        env = os.environ.get("STATE_DIRECTORY")
        candidates = ([Path(env.split(":")[0])] if env else []) + [Path("moi-state"), SYSTEM_STATE_DIR]
    for d in candidates:
        if (d / DB_NAME).exists():
            return d
    tried = ", ".join(str(d / DB_NAME) for d in candidates)
    raise InputFileError(f"no result store found (looked for {tried}); give --state-dir DIR or --config FILE")


def parse_time(text: str) -> float:
    """ISO 8601 date or date-time (UTC unless it has an offset) → Unix time, s."""
    try:
        dt = datetime.fromisoformat(text)
    except ValueError:
        raise InputFileError(f"{text!r} is not a date or date-time; expected e.g. 2025-03-01 or 2025-03-01T12:00") from None
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=UTC)
    return dt.timestamp()
