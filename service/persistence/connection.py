"""Opening the result store's SQLite file and what its errors mean: the read-only connection, the damage
codes, and the decorator that turns an SQLite error into one line naming the file (``StoreError``,
``StoreDamaged`` when the file is damaged)."""

from __future__ import annotations

import functools
import json
import sqlite3
import zlib
from pathlib import Path
from typing import Any, Callable

from service.errors import StoreDamaged, StoreError


def read_only_connection(path: Path) -> sqlite3.Connection:
    """A connection that never writes. WAL mode needs the -shm file, which a read-only directory
    cannot get; with no -wal file nothing waits to be checkpointed, so the file is read as it is."""
    def connect(mode: str) -> sqlite3.Connection:
        db = sqlite3.connect(f"file:{path}?{mode}", uri=True, isolation_level=None, check_same_thread=False,
                             timeout=10.0)
        try:
            db.execute("SELECT 1 FROM sqlite_master LIMIT 1").fetchall()
        except BaseException:
            db.close()
            raise
        return db

    try:
        return connect("mode=ro")
    except sqlite3.OperationalError:
        if Path(f"{path}-wal").exists():
            raise
        return connect("mode=ro&immutable=1")


#: SQLite's primary result codes that mean a damaged file (SQLITE_CORRUPT, SQLITE_NOTADB)
_DAMAGED_CODES = {11, 26}


#: what Python's sqlite3 says of a text column whose bytes are not UTF-8: the store writes only UTF-8, so a page
#: overwritten (the tail of a row on a trace's overflow page: the operator, the part ID)
_UNDECODABLE = "Could not decode to UTF-8"


def is_damage(exc: BaseException) -> bool:
    if isinstance(exc, sqlite3.Error):
        code = getattr(exc, "sqlite_errorcode", None)
        return (code is not None and code & 0xFF in _DAMAGED_CODES) or _UNDECODABLE in str(exc)
    return isinstance(exc, (zlib.error, json.JSONDecodeError))  # a blob or a JSON text that no longer decodes


def store_errors(what: str) -> Callable:
    """Method decorator: an SQLite error (or a stored value that no longer decodes) becomes one
    StoreError line naming the file and what was being done; StoreDamaged when the file is damaged."""

    def wrap(method: Callable) -> Callable:
        @functools.wraps(method)
        def guarded(self: Any, *args: Any, **kwargs: Any) -> Any:
            try:
                return method(self, *args, **kwargs)
            except StoreError:
                raise
            except (sqlite3.Error, zlib.error, json.JSONDecodeError) as exc:
                if is_damage(exc):
                    self.damage = f"{exc} while {what}"
                    raise StoreDamaged(f"the result store {str(self.path)!r} is damaged ({exc}) while {what}; "
                                       "`moi store check` tells what can be read, `moi store salvage` keeps it") from None
                raise StoreError(f"cannot use the result store {str(self.path)!r} while {what}: {exc}") from None

        return guarded

    return wrap
