"""The result store's tables: the measurement columns (how each is written, read back and decoded), the SQL
that makes the tables, and how a store of an older schema gains what it lacks when opened.

``COLUMNS`` is the one place the store's SQL (the table, the migration, the INSERT, the SELECTs), the row →
``StoredMeasurement`` decoding and the salvage's checks come from.
"""

from __future__ import annotations

import json
import sqlite3
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from service.core.vocabulary import operator_of
from service.errors import StoreError

SCHEMA_VERSION = 4  # 2: part, recipe and verdict columns (added in place to a version-1 store);
                    # 3: the outbox row names its consumer (the publisher delivering it; rows of an older store: mqtt);
                    # 4: the operator of each run (empty where the trigger says it, as on the rows of an older store)


@dataclass(frozen=True)
class Column:
    """One column of ``measurements``: its name (the ``StoredMeasurement`` field it reads back as), its SQL type
    and constraints, how its text or blob decodes, which reads select it, the store schema that added it,
    and how ``Store.record`` gets its value from what it is given (``Given``)."""

    name: str
    sql: str
    #: "" as stored; "json": a JSON text; "flags": a JSON list read back as a tuple; "array": a packed float64 array
    codec: str = ""
    #: "list": every read (listings); "full": a single measurement, the latest, a search page; "trace": with its trace
    read: str = "list"
    #: the store schema that added it: an older store gains it by ``ALTER TABLE`` when opened
    since: int = 1
    #: in the listing (``StoredMeasurement.summary``)
    summary: bool = True
    #: its value in the INSERT of a new measurement; None: not written there (the row id, the publication time)
    value: Callable[[Given], Any] | None = None


@dataclass(frozen=True)
class Given:
    """What ``Store.record`` has for a new row: its arguments (``result``: ``IdentificationResult.to_dict()``;
    ``part``: the part columns' values), the numbers it drew and the payload text."""

    uuid: str
    seq: int
    stored_at: float
    payload: str | None
    args: Mapping[str, Any]

    @property
    def result(self) -> Mapping[str, Any]:
        return self.args.get("result") or {}

    @property
    def part(self) -> Mapping[str, Any]:
        return self.args.get("part") or {}


def _arg(name: str) -> Callable[[Given], Any]:
    return lambda g: g.args[name]


def _result(name: str) -> Callable[[Given], Any]:
    return lambda g: g.result.get(name)


def _part(name: str) -> Callable[[Given], Any]:
    return lambda g: g.part.get(name)


def _json(name: str, **kw: Any) -> Callable[[Given], Any]:
    return lambda g: json.dumps(g.args[name], **kw) if g.args[name] is not None else None


def _packed(name: str) -> Callable[[Given], Any]:
    return lambda g: pack(g.args[name])


def _operator(g: Given) -> str | None:
    """The operator the recorder names, stored only when its trigger does not say it (``operator_of``): a column
    added by ALTER TABLE sits after the trace's blobs, on their overflow pages, and an empty one keeps a listing
    from reading through them (and a damaged trace page from costing the row); read back from the trigger."""
    given = g.args.get("operator")
    return given if given and given != operator_of(g.args["trigger"]) else None


#: every column of ``measurements``, in the table's order: the one place the store's SQL (the table, the
#: migration, the INSERT, the SELECTs), the row → ``StoredMeasurement`` decoding and the salvage's checks come from
COLUMNS: tuple[Column, ...] = (
    Column("id", "INTEGER PRIMARY KEY", summary=False),
    Column("uuid", "TEXT NOT NULL UNIQUE", value=lambda g: g.uuid),
    Column("seq", "INTEGER NOT NULL UNIQUE", value=lambda g: g.seq),
    Column("status", "TEXT NOT NULL CHECK (status IN ('ok', 'failed', 'aborted'))", value=_arg("status")),
    Column("trigger", "TEXT NOT NULL", value=_arg("trigger")),
    Column("device_id", "TEXT NOT NULL", value=_arg("device_id")),
    Column("software_version", "TEXT NOT NULL", value=_arg("software_version")),
    Column("started_at", "REAL NOT NULL", value=_arg("started_at")),
    Column("finished_at", "REAL NOT NULL", value=_arg("finished_at")),
    Column("stored_at", "REAL NOT NULL", summary=False, value=lambda g: g.stored_at),
    Column("published_at", "REAL"),                       # set when its last outbox row is acknowledged
    Column("J", "REAL", value=_result("J")),               # kg·m²
    Column("J_std", "REAL", value=_result("J_std")),       # kg·m²
    Column("omega_n", "REAL", value=_result("omega_n")),   # rad/s
    Column("damping_ratio", "REAL", value=_result("damping_ratio")),
    Column("residual_rms", "REAL", value=_result("residual_rms")),  # rad
    Column("flags", "TEXT NOT NULL DEFAULT '[]'", codec="flags",
           value=lambda g: json.dumps(list(g.result.get("flags") or []))),
    Column("error", "TEXT", value=_arg("error")),
    Column("payload", "TEXT", codec="json", read="full", summary=False, value=lambda g: g.payload),
    Column("rig", "TEXT", codec="json", read="full", summary=False, value=_json("rig")),
    Column("config", "TEXT", codec="json", read="full", summary=False, value=_json("config")),
    Column("trace_t", "BLOB", codec="array", read="trace", summary=False, value=_packed("trace_t")),  # s
    Column("trace_angle", "BLOB", codec="array", read="trace", summary=False, value=_packed("trace_angle")),  # rad
    Column("trace_meta", "TEXT", codec="json", read="trace", summary=False, value=_json("trace_meta", default=str)),
    # schema 2: the part, recipe and verdict
    Column("part_id", "TEXT", since=2, value=_part("part_id")),    # the part's serial number (PLC / MQTT)
    Column("part_uuid", "TEXT", since=2, value=_part("part_uuid")),  # the part: every release of one part shares it
    Column("recipe", "TEXT", since=2, value=_part("recipe")),        # recipe name
    Column("recipe_version", "TEXT", since=2, value=_part("recipe_version")),  # hash of the recipe file as used
    Column("release_index", "INTEGER", since=2, value=_part("release_index")),  # 1 … releases
    Column("releases", "INTEGER", since=2, value=_part("releases")),  # releases per part of the recipe
    Column("verdict", "TEXT", since=2, value=_part("verdict")),      # this release's verdict: OK / NOK / INVALID
    Column("part_verdict", "TEXT", since=2, value=_part("part_verdict")),  # the part's, on the release completing it
    Column("part_value", "REAL", since=2, value=_part("part_value")),  # the part's combined value, kg·m²
    Column("part_U", "REAL", since=2, value=_part("part_U")),        # its expanded uncertainty, kg·m²
    # schema 4: who measured (the appraiser of a Gauge R&R), NULL where the trigger says it (read back from it);
    # not in the listing's summary, so the exports and `moi results --json` keep their keys
    Column("operator", "TEXT", since=4, summary=False, value=_operator),
)

_READS = {"list": ("list",), "full": ("list", "full")}


def columns(read: str, *, trace: bool = False) -> tuple[Column, ...]:
    """The columns a read selects: "list" or "full", with the trace or without."""
    groups = _READS[read] + (("trace",) if trace else ())
    return tuple(c for c in COLUMNS if c.read in groups)


def select(columns: Sequence[Column]) -> str:
    return ", ".join(c.name for c in columns)


INSERTED = tuple(c for c in COLUMNS if c.value is not None)
INSERT = (f"INSERT INTO measurements ({select(INSERTED)}) "
           f"VALUES ({', '.join('?' * len(INSERTED))})")
#: the columns that hold JSON text, and those that hold packed arrays (the salvage checks that they decode)
JSON_COLUMNS = tuple(c.name for c in COLUMNS if c.codec in ("json", "flags"))
ARRAY_COLUMNS = tuple(c.name for c in COLUMNS if c.codec == "array")
#: the measurements table as the first store schema made it (later columns are added by ALTER TABLE at open)
_MEASUREMENTS = ("CREATE TABLE IF NOT EXISTS measurements (\n"
                 + ",\n".join(f"    {c.name:<16} {c.sql}" for c in COLUMNS if c.since == 1) + "\n);\n")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
""" + _MEASUREMENTS + """CREATE INDEX IF NOT EXISTS measurements_finished ON measurements (finished_at);
CREATE TABLE IF NOT EXISTS outbox (
    id             INTEGER PRIMARY KEY,
    measurement_id INTEGER NOT NULL REFERENCES measurements (id),
    uuid           TEXT NOT NULL,
    kind           TEXT NOT NULL,
    payload        TEXT NOT NULL,
    created_at     REAL NOT NULL,
    attempts       INTEGER NOT NULL DEFAULT 0,
    last_attempt   REAL
);
CREATE TABLE IF NOT EXISTS attachments (
    uuid       TEXT NOT NULL REFERENCES measurements (uuid),
    name       TEXT NOT NULL,
    media_type TEXT NOT NULL,
    data       BLOB NOT NULL,
    created_at REAL NOT NULL,
    PRIMARY KEY (uuid, name)
);
"""

#: the tensor sets (a guided multi-orientation set of a tensor recipe): one row per set, linked to the
#: releases that count for each orientation (their UUIDs in ``releases``); a table of its own, so a store
#: of an older version opens and gains it unchanged
_TENSOR_SCHEMA = """
CREATE TABLE IF NOT EXISTS tensor_sets (
    id          INTEGER PRIMARY KEY,
    uuid        TEXT NOT NULL UNIQUE,
    status      TEXT NOT NULL CHECK (status IN ('complete', 'aborted', 'failed')),
    recipe      TEXT,
    part_id     TEXT,
    started_at  REAL,
    finished_at REAL NOT NULL,
    flags       TEXT NOT NULL DEFAULT '[]',
    releases    TEXT NOT NULL,
    record      TEXT NOT NULL
);
"""


#: check standards: a reference artifact of certified J ± U measured, its normalised error E_n
#: (``measurement.uncertainty.CheckStandard``); a table of its own, so an older store gains it unchanged
_CHECK_SCHEMA = """
CREATE TABLE IF NOT EXISTS check_standards (
    id          INTEGER PRIMARY KEY,
    name        TEXT NOT NULL,
    finished_at REAL NOT NULL,
    passed      INTEGER NOT NULL,
    record      TEXT NOT NULL
);
"""


#: gauge studies (a Type 1 study of a reference part: ``service.parts.gauge_study``): one row per study, linked to
#: the releases that counted (their UUIDs in ``releases``); a table of its own, so an older store gains it unchanged
_GAUGE_SCHEMA = """
CREATE TABLE IF NOT EXISTS gauge_studies (
    id          INTEGER PRIMARY KEY,
    uuid        TEXT NOT NULL UNIQUE,
    kind        TEXT NOT NULL,
    status      TEXT NOT NULL CHECK (status IN ('complete', 'aborted', 'failed')),
    recipe      TEXT,
    started_at  REAL,
    finished_at REAL NOT NULL,
    releases    TEXT NOT NULL,
    record      TEXT NOT NULL
);
"""


#: the consumer of the outbox rows of a store made before rows named theirs (only MQTT delivered from it)
LEGACY_CONSUMER = "mqtt"
#: schema 3: which publisher delivers the row (``Publisher.NAME``); each consumer acknowledges its own rows
_OUTBOX_CONSUMER = f"consumer TEXT NOT NULL DEFAULT '{LEGACY_CONSUMER}'"


def pack(a: np.ndarray | None) -> bytes | None:
    if a is None:
        return None
    return zlib.compress(np.ascontiguousarray(a, dtype="<f8").tobytes(), 6)


def unpack(b: bytes | None) -> np.ndarray | None:
    if b is None:
        return None
    return np.frombuffer(zlib.decompress(b), dtype="<f8").copy()


def create_tables(db: sqlite3.Connection) -> None:
    """Make the tables a store needs and add the columns an older store lacks (idempotent: IF NOT EXISTS)."""
    db.executescript(_SCHEMA)
    db.executescript(_TENSOR_SCHEMA)
    db.executescript(_CHECK_SCHEMA)
    db.executescript(_GAUGE_SCHEMA)
    have = {row[1] for row in db.execute("PRAGMA table_info(measurements)")}
    for c in COLUMNS:
        if c.name not in have:
            db.execute(f"ALTER TABLE measurements ADD COLUMN {c.name} {c.sql}")
    if "consumer" not in {row[1] for row in db.execute("PRAGMA table_info(outbox)")}:
        db.execute(f"ALTER TABLE outbox ADD COLUMN {_OUTBOX_CONSUMER}")
    db.execute("CREATE INDEX IF NOT EXISTS outbox_consumer ON outbox (consumer, id)")
    db.execute("CREATE INDEX IF NOT EXISTS measurements_part ON measurements (part_id)")


def check_version(path: Path, found: str | None) -> None:
    """Refuse a store written by newer software (its schema version ``found``; None: not yet written)."""
    if found is not None and int(found) > SCHEMA_VERSION:
        raise StoreError(f"{path}: result store schema {found} is newer than this software ({SCHEMA_VERSION})")


def mark_version(db: sqlite3.Connection, path: Path) -> None:
    """Write this software's schema version into the store (in the caller's transaction)."""
    row = db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()
    check_version(path, row[0] if row is not None else None)
    if row is None:
        db.execute("INSERT INTO meta (key, value) VALUES ('schema', ?)", (str(SCHEMA_VERSION),))
    elif int(row[0]) < SCHEMA_VERSION:
        db.execute("UPDATE meta SET value = ? WHERE key='schema'", (str(SCHEMA_VERSION),))
