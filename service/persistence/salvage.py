"""A damaged result store: check what can be read, salvage it into a new store, quarantine the damaged file.

A store that SQLite reports as damaged (``service.errors.StoreDamaged``) is moved aside by the daemon at start
(``quarantine_store``); ``moi store check`` and ``moi store salvage`` do the same by hand. Every row that can be
read is copied, with its sequence number: a PLC keyed on ``seq`` never sees an old number again. What cannot be
read is counted and said, never silently left out.
"""

from __future__ import annotations

import json
import os
import sqlite3
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

from service.errors import StoreError
from service.persistence.connection import read_only_connection
from service.persistence.pages import leaf_records
from service.persistence.sequence import read_seq_floor
from service.persistence.store import DB_NAME, Store
from service.persistence.tables import ARRAY_COLUMNS, JSON_COLUMNS, LEGACY_CONSUMER, unpack

#: tables read back by check and salvage, in the order rows are copied (foreign keys point backwards)
_TABLES = ("measurements", "outbox", "attachments")


@dataclass
class StoreHealth:
    """What ``check_store``/``salvage_store`` could read: rows per table, rows lost, SQLite's own findings."""

    path: str
    readable: dict[str, int]
    lost: dict[str, int]
    problems: list[str]

    @property
    def ok(self) -> bool:
        return not self.problems and not any(self.lost.values())

    def summary(self) -> str:
        read = ", ".join(f"{n} {t}" for t, n in self.readable.items())
        lost = ", ".join(f"{n} {t}" for t, n in self.lost.items() if n)
        return f"{self.path}: " + ("intact" if self.ok else "damaged") + f"; readable: {read}" + \
            (f"; lost: {lost}" if lost else "")


def _open_read_only(path: Path) -> sqlite3.Connection:
    if not path.exists():
        raise StoreError(f"no result store at {str(path)!r}")
    try:
        return read_only_connection(path)
    except sqlite3.Error as exc:
        raise StoreError(f"cannot read {str(path)!r}: {exc}") from None


def _rowids(db: sqlite3.Connection, table: str, max_probes: int = 100_000) -> Iterator[int]:
    """The rowids of ``table`` that can be reached. A scan stops at a damaged page; the rowids
    after it are found by seeking past it (bounded number of seeks)."""
    last = 0
    probes = 0
    while probes < max_probes:
        try:
            for (rowid,) in db.execute(f"SELECT rowid FROM {table} WHERE rowid > ? ORDER BY rowid", (last,)):
                last = rowid
                yield rowid
            return
        except sqlite3.DatabaseError:
            probes += 1
            last += 1  # step over the rowid the damaged page hides


def _read_rows(db: sqlite3.Connection, table: str, health: StoreHealth) -> Iterator[tuple[list[str], tuple]]:
    """Every readable row of ``table`` (column names, values); unreadable ones are counted as lost."""
    try:
        columns = [r[1] for r in db.execute(f"PRAGMA table_info({table})")]
        ids = list(_rowids(db, table))
    except sqlite3.DatabaseError as exc:
        health.problems.append(f"{table}: not readable ({exc})")
        return
    indexed = _indexed_count(db, table)
    if indexed is not None and indexed > len(ids):
        # rows the table's own tree no longer reaches (a damaged root or inner page) are still listed in
        # its unique index, and their leaf pages are usually intact: read them there; what cannot be read
        # is lost, and said so, not silently left out
        unreached = indexed - len(ids)
        found = _rows_from_leaf_pages(db, table, columns, set(ids))
        health.lost[table] += unreached - len(found)
        health.readable[table] += len(found)
        health.problems.append(f"{table}: {unreached} row(s) listed in its index cannot be reached through the "
                               f"table; {len(found)} read from its leaf pages")
        yield from ((columns, row) for row in found)
    for rowid in ids:
        row = _read_row(db, table, columns, rowid)
        if row is None and table == "measurements":
            # the trace's pages are the bulk of the file: keep the result without it rather than nothing
            row = _read_row(db, table, columns, rowid, without=ARRAY_COLUMNS)
            if row is not None:
                health.problems.append(f"measurement row {rowid}: trace not readable (kept without it)")
        if row is None:
            health.lost[table] += 1
            continue
        health.readable[table] += 1
        yield columns, row


#: a unique index of each table that lists every row (its count needs no page of the table itself)
_ROW_INDEXES = {"measurements": "sqlite_autoindex_measurements_1"}


def _indexed_count(db: sqlite3.Connection, table: str) -> int | None:
    """The rows of ``table`` by its unique index, or None (no such index, or it is damaged too)."""
    index = _ROW_INDEXES.get(table)
    if index is None:
        return None
    try:
        return int(db.execute(f"SELECT count(uuid) FROM {table} INDEXED BY {index}").fetchone()[0])
    except sqlite3.DatabaseError:
        return None


def _rows_from_leaf_pages(db: sqlite3.Connection, table: str, columns: list[str], reached: set[int]) -> list[tuple]:
    """Rows of ``table`` its tree does not reach, read from the file's leaf pages (``pages.leaf_records``).

    A leaf page does not say which table it belongs to, and a page may hold a stale copy of a row: a
    record is taken only when its uuid is listed in the table's intact unique index, it has the table's
    shape (ALTER TABLE columns missing at the end read as NULL), its JSON and arrays decode, and no
    other record claims that uuid."""
    index = _ROW_INDEXES.get(table)
    if index is None or "uuid" not in columns:
        return []
    try:
        listed = {u for (u,) in db.execute(f"SELECT uuid FROM {table} INDEXED BY {index}")}
        file = next(r[2] for r in db.execute("PRAGMA database_list") if r[1] == "main")
        pk = [r[1] for r in db.execute(f"PRAGMA table_info({table})") if r[5] == 1 and r[2].upper() == "INTEGER"]
    except (sqlite3.DatabaseError, StopIteration):
        return []
    at_uuid = columns.index("uuid")
    found: dict[str, tuple] = {}
    claimed: dict[str, int] = {}
    try:
        # the rows the tree reaches are copied already: their cells (and traces) are not decoded again
        records = leaf_records(file, wanted=lambda rowid: rowid not in reached)
        for rec in records:
            if not at_uuid < len(rec.values) <= len(columns):
                continue
            values = list(rec.values) + [None] * (len(columns) - len(rec.values))
            for name in pk:  # an INTEGER PRIMARY KEY is the rowid itself: the record stores NULL there
                values[columns.index(name)] = rec.rowid
            uuid = values[at_uuid]
            if uuid not in listed or not _decodes(table, dict(zip(columns, values))):
                continue
            claimed[uuid] = claimed.get(uuid, 0) + 1
            found[uuid] = tuple(values)
    except (OSError, ValueError):
        return []  # the file cannot be mapped, or its header is gone: nothing to read from its pages
    return [row for uuid, row in found.items() if claimed[uuid] == 1]


def _decodes(table: str, d: Mapping[str, Any]) -> bool:
    """Whether a row's JSON texts and packed arrays decode."""
    if table != "measurements":
        return True
    try:
        for k in JSON_COLUMNS:
            if d.get(k) is not None:
                json.loads(d[k])
        for k in ARRAY_COLUMNS:
            unpack(d.get(k))
    except (zlib.error, json.JSONDecodeError, UnicodeDecodeError, TypeError, ValueError):
        return False
    return True


def _read_row(db: sqlite3.Connection, table: str, columns: list[str], rowid: int,
              without: tuple[str, ...] = ()) -> tuple | None:
    """One row whose blobs and JSON texts decode, or None; the columns in ``without`` read as NULL."""
    wanted = [c if c not in without else "NULL" for c in columns]
    try:
        row = db.execute(f"SELECT {', '.join(wanted)} FROM {table} WHERE rowid = ?", (rowid,)).fetchone()
    except sqlite3.DatabaseError:
        return None
    return row if row is None or _decodes(table, dict(zip(columns, row))) else None


def check_store(path: str | Path) -> StoreHealth:
    """Read every row of the store at ``path`` (results.db) without changing it; say what is damaged."""
    path = Path(path)
    health = StoreHealth(str(path), dict.fromkeys(_TABLES, 0), dict.fromkeys(_TABLES, 0), [])
    db = _open_read_only(path)
    try:
        try:
            found = [r[0] for r in db.execute("PRAGMA integrity_check(20)")]
            if found != ["ok"]:
                health.problems += found
        except sqlite3.DatabaseError as exc:
            health.problems.append(str(exc))
        for table in _TABLES:
            for _ in _read_rows(db, table, health):
                pass
    finally:
        db.close()
    return health


def salvage_store(path: str | Path, dest_dir: str | Path) -> StoreHealth:
    """Copy every readable row of the store at ``path`` into a new store in ``dest_dir`` (which
    must not hold one yet). Sequence numbers are kept and never reused."""
    path, dest = Path(path), Path(dest_dir)
    if (dest / DB_NAME).exists():
        raise StoreError(f"{str(dest / DB_NAME)!r} exists already: salvage into an empty directory")
    health = StoreHealth(str(path), dict.fromkeys(_TABLES, 0), dict.fromkeys(_TABLES, 0), [])
    try:
        src = _open_read_only(path)
    except StoreError as exc:
        if not path.exists():
            raise
        # nothing is readable (the header is gone): an empty store that goes on counting where the old one was
        health.problems.append(str(exc))
        with Store(dest) as new, new.transaction() as db:
            db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES ('last_seq', ?)",
                       (str(read_seq_floor(path.parent)),))
        return health
    try:
        with Store(dest) as new, new.transaction() as db:
            max_seq = 0
            for table in _TABLES:
                for columns, row in _read_rows(src, table, health):
                    try:
                        db.execute(f"INSERT OR IGNORE INTO {table} ({', '.join(columns)}) "
                                   f"VALUES ({', '.join('?' * len(columns))})", row)
                    except sqlite3.IntegrityError:  # e.g. an outbox row whose measurement was lost
                        health.readable[table] -= 1
                        health.lost[table] += 1
                        continue
                    if table == "measurements":
                        max_seq = max(max_seq, int(row[columns.index("seq")]))
            outbox_used = health.readable["outbox"] + health.lost["outbox"] > 0 or \
                    any(p.startswith("outbox:") for p in health.problems)
            if outbox_used:
                # an unsent result whose outbox row was on a lost page is queued again from its stored
                # payload, for each consumer seen in the outbox (consumers dedupe by uuid); without a
                # publisher delivering from the outbox nothing was ever queued
                consumers = [r[0] for r in db.execute("SELECT DISTINCT consumer FROM outbox")] or [LEGACY_CONSUMER]
                requeued = sum(db.execute(
                    "INSERT INTO outbox (measurement_id, uuid, kind, payload, created_at, consumer) "
                    "SELECT id, uuid, 'result', payload, stored_at, ? FROM measurements m WHERE status = 'ok' "
                    "AND payload IS NOT NULL AND published_at IS NULL AND NOT EXISTS "
                    "(SELECT 1 FROM outbox o WHERE o.measurement_id = m.id AND o.consumer = ?)",
                    (c, c)).rowcount for c in consumers)
                if requeued:
                    health.problems.append(f"outbox: {requeued} unsent result(s) queued again from their "
                                           "stored payload")
            try:
                counter = src.execute("SELECT value FROM meta WHERE key='last_seq'").fetchone()
                max_seq = max(max_seq, int(counter[0])) if counter else max_seq
            except (sqlite3.DatabaseError, ValueError):
                pass  # the counter is lost: the largest salvaged seq is the floor
            # the copy of the counter beside the file: a PLC keyed on seq never sees an old number again,
            # even when the header (and with it every row) is gone
            max_seq = max(max_seq, read_seq_floor(path.parent))
            db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES ('last_seq', ?)", (str(max_seq),))
    finally:
        src.close()
    return health


def quarantine_store(state_dir: str | Path, clock: Callable[[], float] = time.time) -> tuple[Path, StoreHealth]:
    """Move a damaged results.db (with its -wal and -shm files) aside and salvage what can be read
    into a new results.db. Returns (where the damaged file now is, what was salvaged)."""
    state = Path(state_dir)
    db = state / DB_NAME
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(clock()))
    aside = state / f"{DB_NAME}.damaged-{stamp}"
    for suffix in ("", "-wal", "-shm"):  # SQLite pairs "<name>-wal" with "<name>": they move together
        if Path(f"{db}{suffix}").exists():
            os.replace(f"{db}{suffix}", f"{aside}{suffix}")
    return aside, salvage_store(aside, state)
