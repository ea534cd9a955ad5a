"""The result store: every measurement in SQLite (WAL) in the state directory.

One row per measurement (ok, failed or aborted) with the raw trace, the
published payload (which contains ``IdentificationResult.to_dict()``), the rig
and configuration used, timestamps and the software version. The outbox (the
publications of each store-and-forward publisher: MQTT, Sparkplug) lives in the same database so that a result and its pending publication are
written in one transaction, before anything is published: a crash either
loses the measurement entirely (it never reached the store, nothing was
published) or keeps both.

Durability: WAL with ``synchronous=FULL`` (a power cut after commit keeps the
row). One connection guarded by a lock is shared by the daemon's threads.
"""

from __future__ import annotations

import builtins
import contextlib
import dataclasses
import functools
import json
import os
import sqlite3
import threading
import time
import uuid as uuidlib
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from service.errors import StoreDamaged, StoreError

DB_NAME = "results.db"
#: the largest integer SQLite stores (a longer sequence number is no measurement's)
SQLITE_MAX_INTEGER = 2**63 - 1
SCHEMA_VERSION = 3  # 2: part, recipe and verdict columns (added in place to a version-1 store);
                    # 3: the outbox row names its consumer (the publisher delivering it; rows of an older store: mqtt)



@dataclass(frozen=True)
class Column:
    """One column of ``measurements``: its name (the ``StoredMeasurement`` field it reads back as), its SQL type
    and constraints, how its text or blob decodes, which reads select it, the store schema that added it,
    and how ``Store.record`` gets its value from what it is given (``_Given``)."""

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
    value: Callable[[_Given], Any] | None = None


@dataclass(frozen=True)
class _Given:
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


def _arg(name: str) -> Callable[[_Given], Any]:
    return lambda g: g.args[name]


def _result(name: str) -> Callable[[_Given], Any]:
    return lambda g: g.result.get(name)


def _part(name: str) -> Callable[[_Given], Any]:
    return lambda g: g.part.get(name)


def _json(name: str, **kw: Any) -> Callable[[_Given], Any]:
    return lambda g: json.dumps(g.args[name], **kw) if g.args[name] is not None else None


def _packed(name: str) -> Callable[[_Given], Any]:
    return lambda g: _pack(g.args[name])


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
)

_READS = {"list": ("list",), "full": ("list", "full")}


def _columns(read: str, *, trace: bool = False) -> tuple[Column, ...]:
    """The columns a read selects: "list" or "full", with the trace or without."""
    groups = _READS[read] + (("trace",) if trace else ())
    return tuple(c for c in COLUMNS if c.read in groups)


def _select(columns: Sequence[Column]) -> str:
    return ", ".join(c.name for c in columns)


_INSERTED = tuple(c for c in COLUMNS if c.value is not None)
_INSERT = (f"INSERT INTO measurements ({_select(_INSERTED)}) "
           f"VALUES ({', '.join('?' * len(_INSERTED))})")
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


def _is_damage(exc: BaseException) -> bool:
    if isinstance(exc, sqlite3.Error):
        code = getattr(exc, "sqlite_errorcode", None)
        return code is not None and code & 0xFF in _DAMAGED_CODES
    return isinstance(exc, (zlib.error, json.JSONDecodeError))  # a blob or a JSON text that no longer decodes


def _store_errors(what: str) -> Callable:
    """Method decorator: an SQLite error (or a stored value that no longer decodes) becomes one
    StoreError line naming the file and what was being done; StoreDamaged when the file is damaged."""

    def wrap(method: Callable) -> Callable:
        @functools.wraps(method)
        def guarded(self: "Store", *args: Any, **kwargs: Any) -> Any:
            try:
                return method(self, *args, **kwargs)
            except StoreError:
                raise
            except (sqlite3.Error, zlib.error, json.JSONDecodeError) as exc:
                if _is_damage(exc):
                    self.damage = f"{exc} while {what}"
                    raise StoreDamaged(f"the result store {str(self.path)!r} is damaged ({exc}) while {what}; "
                                       "`moi store check` tells what can be read, `moi store salvage` keeps it") from None
                raise StoreError(f"cannot use the result store {str(self.path)!r} while {what}: {exc}") from None

        return guarded

    return wrap


def _pack(a: np.ndarray | None) -> bytes | None:
    if a is None:
        return None
    return zlib.compress(np.ascontiguousarray(a, dtype="<f8").tobytes(), 6)


def unpack(b: bytes | None) -> np.ndarray | None:
    if b is None:
        return None
    return np.frombuffer(zlib.decompress(b), dtype="<f8").copy()


@dataclass(frozen=True)
class StoredMeasurement:
    """One stored measurement as read back from the store (times: Unix s; trace arrays: s and rad).

    Not ``firmware_host.Measurement``, which is what the sequencer hands to the store.
    """

    id: int
    uuid: str
    seq: int
    status: str
    trigger: str
    device_id: str
    software_version: str
    started_at: float
    finished_at: float
    stored_at: float
    published_at: float | None
    J: float | None
    J_std: float | None
    omega_n: float | None
    damping_ratio: float | None
    residual_rms: float | None
    flags: tuple[str, ...]
    error: str | None
    payload: dict[str, Any] | None = None
    rig: dict[str, Any] | None = None
    config: dict[str, Any] | None = None
    trace_t: np.ndarray | None = None
    trace_angle: np.ndarray | None = None
    trace_meta: dict[str, Any] | None = None
    part_id: str | None = None
    part_uuid: str | None = None
    recipe: str | None = None
    recipe_version: str | None = None
    release_index: int | None = None
    releases: int | None = None
    verdict: str | None = None
    part_verdict: str | None = None
    part_value: float | None = None
    part_U: float | None = None

    def summary(self) -> dict[str, Any]:
        """The listing fields (no payload, no trace)."""
        return {c.name: list(self.flags) if c.codec == "flags" else getattr(self, c.name)
                for c in COLUMNS if c.summary}


@dataclass(frozen=True)
class OutboxItem:
    id: int
    uuid: str
    kind: str
    payload: str
    attempts: int


#: the consumer of the outbox rows of a store made before rows named theirs (only MQTT delivered from it)
LEGACY_CONSUMER = "mqtt"
#: schema 3: which publisher delivers the row (``Publisher.NAME``); each consumer acknowledges its own rows
_OUTBOX_CONSUMER = f"consumer TEXT NOT NULL DEFAULT '{LEGACY_CONSUMER}'"


# the typed mirror of the column table: a column and its field come and go together
assert [f.name for f in dataclasses.fields(StoredMeasurement)] == [c.name for c in COLUMNS]


class Store:
    """The SQLite result store and outbox in ``state_dir``/results.db."""

    def __init__(self, state_dir: str | Path, *, create: bool = True, read_only: bool = False) -> None:
        self.state_dir = Path(state_dir)
        self.path = self.state_dir / DB_NAME
        if (not create or read_only) and not self.path.exists():
            raise StoreError(f"no result store at {str(self.path)!r}")
        self._lock = threading.RLock()
        if read_only:
            self._open_read_only()
            return
        try:
            self.state_dir.mkdir(parents=True, exist_ok=True)
            # isolation_level=None: explicit BEGIN/COMMIT, no implicit transactions
            self._db = sqlite3.connect(str(self.path), isolation_level=None, check_same_thread=False, timeout=10.0)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute("PRAGMA foreign_keys=ON")
            self._db.executescript(_SCHEMA)  # idempotent (IF NOT EXISTS)
            self._db.executescript(_TENSOR_SCHEMA)
            self._db.executescript(_CHECK_SCHEMA)
            have = {row[1] for row in self._db.execute("PRAGMA table_info(measurements)")}
            for c in COLUMNS:
                if c.name not in have:
                    self._db.execute(f"ALTER TABLE measurements ADD COLUMN {c.name} {c.sql}")
            if "consumer" not in {row[1] for row in self._db.execute("PRAGMA table_info(outbox)")}:
                self._db.execute(f"ALTER TABLE outbox ADD COLUMN {_OUTBOX_CONSUMER}")
            self._db.execute("CREATE INDEX IF NOT EXISTS outbox_consumer ON outbox (consumer, id)")
            self._db.execute("CREATE INDEX IF NOT EXISTS measurements_part ON measurements (part_id)")
            with self._tx():
                row = self._db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()
                if row is None:
                    self._db.execute("INSERT INTO meta (key, value) VALUES ('schema', ?)", (str(SCHEMA_VERSION),))
                elif int(row[0]) > SCHEMA_VERSION:
                    raise StoreError(f"{self.path}: result store schema {row[0]} is newer than this software ({SCHEMA_VERSION})")
                elif int(row[0]) < SCHEMA_VERSION:
                    self._db.execute("UPDATE meta SET value = ? WHERE key='schema'", (str(SCHEMA_VERSION),))
        except sqlite3.Error as exc:
            if _is_damage(exc):
                raise StoreDamaged(f"the result store {str(self.path)!r} is damaged ({exc})") from None
            raise StoreError(f"cannot open the result store {str(self.path)!r}: {exc}") from None
        except OSError as exc:
            raise StoreError(f"cannot create the state directory {str(self.state_dir)!r}: {exc.strerror}") from None

    def _open_read_only(self) -> None:
        """For the reading commands: nothing is written (no schema, no journal mode, no write lock),
        so a store the user may only read (another user's, a copy on read-only media) opens too."""
        try:
            self._db = read_only_connection(self.path)
            try:
                row = self._db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()
            except BaseException:
                self._db.close()
                raise
        except sqlite3.Error as exc:
            if _is_damage(exc):
                raise StoreDamaged(f"the result store {str(self.path)!r} is damaged ({exc})") from None
            raise StoreError(f"cannot read the result store {str(self.path)!r}: {exc}") from None
        if row is not None and int(row[0]) > SCHEMA_VERSION:
            raise StoreError(f"{self.path}: result store schema {row[0]} is newer than this software ({SCHEMA_VERSION})")
        self.read_only = True

    # --- plumbing -----------------------------------------------------------------
    class _Tx:
        """One write transaction. Every write passes here, so here the store learns whether it can still
        write (``Store.write_failure``); a failed COMMIT (a full disk) is rolled back, or the connection
        would stay in the transaction and refuse every later write even once space is freed."""

        def __init__(self, store: "Store") -> None:
            self.store = store
            self.db = store._db

        def __enter__(self) -> sqlite3.Connection:
            try:
                self.db.execute("BEGIN IMMEDIATE")
            except sqlite3.Error as exc:
                self.store._write_failed(exc)
                raise
            return self.db

        def __exit__(self, exc_type, exc, tb) -> None:
            if exc_type is None:
                try:
                    self.db.execute("COMMIT")
                    self.store.write_failure = None
                    return
                except sqlite3.Error as failed:
                    exc = failed
                    self._rollback()
                    self.store._write_failed(exc)
                    raise
            if isinstance(exc, sqlite3.Error):
                self.store._write_failed(exc)
            self._rollback()

        def _rollback(self) -> None:
            if self.db.in_transaction:
                self.db.execute("ROLLBACK")

    def _tx(self) -> "_Tx":
        return Store._Tx(self)

    @contextlib.contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """The connection, in one write transaction under the store's lock (the salvage copies rows with it)."""
        with self._lock, self._tx() as db:
            yield db

    #: why the last write failed (a full disk, a read-only file), None after a write that succeeded
    write_failure: str | None = None
    #: the damage the store met last (a page of a trace or a plot that no longer reads), None while none
    damage: str | None = None

    def _write_failed(self, exc: sqlite3.Error) -> None:
        self.write_failure = str(exc)

    def writable(self) -> bool:
        """Whether a write succeeds now (a write transaction that changes nothing): after a failed
        write, the way to learn that space was freed."""
        try:
            with self._lock, self._tx() as db:
                db.execute("UPDATE meta SET value = value WHERE key = 'schema'")
        except sqlite3.Error:
            return False
        return True

    read_only = False

    def close(self) -> None:
        with self._lock:
            if self.read_only:
                self._db.close()
                return
            with contextlib.suppress(sqlite3.Error):  # another reader holds the WAL: the checkpoint happens later
                self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            self._db.close()

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- writing ------------------------------------------------------------------
    def record(
        self,
        *,
        status: str,
        trigger: str,
        device_id: str,
        software_version: str,
        started_at: float,
        finished_at: float,
        result: Mapping[str, Any] | None = None,
        build_payload: Callable[[str, int], dict[str, Any]] | None = None,
        error: str | None = None,
        rig: Mapping[str, Any] | None = None,
        config: Mapping[str, Any] | None = None,
        trace_t: np.ndarray | None = None,
        trace_angle: np.ndarray | None = None,
        trace_meta: Mapping[str, Any] | None = None,
        enqueue: Mapping[str, Sequence[str]] | None = None,
        uuid: str | None = None,
        part: Mapping[str, Any] | None = None,
    ) -> StoredMeasurement:
        """Store one measurement and queue its publications, atomically.

        build_payload(uuid, seq) makes the published payload once the sequence
        number is known (ok results). enqueue: the outbox kinds to queue per consumer (the publisher
        that delivers them, e.g. {"mqtt": ("result",)}); the payload is queued as it is stored, one row
        per consumer and kind, each acknowledged by its consumer alone. part: values of
        the schema-2 part columns (``COLUMNS`` with ``since=2``: part ID, recipe, verdicts...), missing keys are NULL.
        """
        from service.persistence.canonical import dumps

        uid = uuid or str(uuidlib.uuid4())
        now = time.time()
        try:
            with self._lock, self._tx() as db:
                seq = int(db.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM measurements").fetchone()[0])
                counter = db.execute("SELECT value FROM meta WHERE key='last_seq'").fetchone()
                if counter is not None:  # never reuse a number, even after rows were pruned
                    seq = max(seq, int(counter[0]) + 1)
                seq = max(seq, read_seq_floor(self.state_dir) + 1)
                db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES ('last_seq', ?)", (str(seq),))
                payload = build_payload(uid, seq) if build_payload is not None else None
                payload_text = dumps(payload) if payload is not None else None
                given = _Given(uid, seq, now, payload_text, dict(
                    status=status, trigger=trigger, device_id=device_id, software_version=software_version,
                    started_at=started_at, finished_at=finished_at, result=result, error=error, rig=rig,
                    config=config, trace_t=trace_t, trace_angle=trace_angle, trace_meta=trace_meta, part=part))
                mid = db.execute(_INSERT, [c.value(given) for c in _INSERTED if c.value is not None]).lastrowid
                if payload_text is not None:
                    for consumer, kinds in (enqueue or {}).items():
                        for kind in kinds:
                            db.execute("INSERT INTO outbox (measurement_id, uuid, kind, payload, created_at, consumer) "
                                       "VALUES (?,?,?,?,?,?)", (mid, uid, kind, payload_text, now, consumer))
        except sqlite3.Error as exc:
            raise StoreError(f"cannot write to the result store {str(self.path)!r}: {exc}") from None
        write_seq_floor(self.state_dir, seq)
        m = self.get(uid)
        assert m is not None
        return m

    # --- outbox -------------------------------------------------------------------
    @_store_errors("reading the outbox")
    def outbox_pending(self, consumer: str | None = None, limit: int = 100,
                       exclude: Sequence[int] = ()) -> list[OutboxItem]:
        """Oldest unacknowledged publications first: a consumer's (a publisher's ``NAME``), or everyone's."""
        where, args = ("WHERE consumer = ? ", (consumer,)) if consumer is not None else ("", ())
        with self._lock:
            rows = self._db.execute(
                f"SELECT id, uuid, kind, payload, attempts FROM outbox {where}ORDER BY id LIMIT ?",
                (*args, limit + len(exclude))).fetchall()
        skip = set(exclude)
        return [OutboxItem(*row) for row in rows if row[0] not in skip][:limit]

    @_store_errors("updating the outbox")
    def outbox_attempt(self, item_id: int) -> None:
        with self._lock, self._tx() as db:
            db.execute("UPDATE outbox SET attempts = attempts + 1, last_attempt = ? WHERE id = ?", (time.time(), item_id))

    @_store_errors("updating the outbox")
    def outbox_ack(self, item_id: int) -> bool:
        """Its consumer delivered the row (the broker acknowledged it): drop it from the outbox. False if it
        was not there. The measurement's ``published_at`` is set when its last row goes: every consumer
        that delivers from the outbox has it."""
        now = time.time()
        with self._lock, self._tx() as db:
            row = db.execute("SELECT measurement_id FROM outbox WHERE id = ?", (item_id,)).fetchone()
            if row is None:
                return False
            db.execute("DELETE FROM outbox WHERE id = ?", (item_id,))
            db.execute("UPDATE measurements SET published_at = COALESCE(published_at, ?) WHERE id = ? "
                       "AND NOT EXISTS (SELECT 1 FROM outbox WHERE measurement_id = ?)", (now, row[0], row[0]))
        return True

    @_store_errors("counting the outbox")
    def outbox_count(self, consumer: str | None = None) -> int:
        """Rows not yet acknowledged: a consumer's, or everyone's."""
        where, args = (" WHERE consumer = ?", (consumer,)) if consumer is not None else ("", ())
        with self._lock:
            return int(self._db.execute(f"SELECT COUNT(*) FROM outbox{where}", args).fetchone()[0])

    # --- reading ------------------------------------------------------------------
    @staticmethod
    def _row(row: Sequence[Any], full: bool, trace: bool) -> StoredMeasurement:
        """A row selected with the columns of ``_columns("full" if full else "list", trace=trace)``."""
        d: dict[str, Any] = {}
        for c, v in zip(_columns("full" if full else "list", trace=trace), row, strict=True):
            if c.codec == "flags":
                v = tuple(json.loads(v or "[]"))
            elif c.codec == "json" and v is not None:
                v = json.loads(v)
            elif c.codec == "array":
                v = unpack(v)
            d[c.name] = v
        return StoredMeasurement(**d)

    @_store_errors("reading a measurement")
    def get(self, key: str | int, *, trace: bool = False) -> StoredMeasurement | None:
        """A measurement by UUID (or a unique UUID prefix) or by sequence number.

        A key of digits only is a sequence number first and a UUID prefix when no measurement has that
        number (a UUID may start with eight digits)."""
        cols = _select(_columns("full", trace=trace))
        with self._lock:
            rows = []
            if (isinstance(key, int) or (isinstance(key, str) and key.isdigit())) and int(key) <= SQLITE_MAX_INTEGER:
                rows = self._db.execute(f"SELECT {cols} FROM measurements WHERE seq = ?", (int(key),)).fetchall()
            if not rows and isinstance(key, str):
                # a prefix, compared literally: '%' and '_' in the key are not wildcards
                rows = self._db.execute(f"SELECT {cols} FROM measurements WHERE substr(uuid, 1, length(?)) = ?",
                                        (str(key), str(key))).fetchall()
        if len(rows) != 1:
            return None
        return self._row(rows[0], full=True, trace=trace)

    @_store_errors("reading a measurement")
    def has_trace(self, uuid: str) -> bool:
        """Whether the measurement ``uuid`` was stored with its trace (without reading the trace)."""
        with self._lock:
            row = self._db.execute("SELECT trace_t IS NOT NULL FROM measurements WHERE uuid = ?", (uuid,)).fetchone()
        return bool(row and row[0])

    @_store_errors("reading the latest measurement")
    def latest(self, status: str | None = "ok") -> StoredMeasurement | None:
        where = "WHERE status = ?" if status else ""
        args: tuple = (status,) if status else ()
        with self._lock:
            row = self._db.execute(f"SELECT {_select(_columns('full'))} FROM measurements {where} "
                                   "ORDER BY seq DESC LIMIT 1", args).fetchone()
        return self._row(row, full=True, trace=False) if row else None

    @_store_errors("listing measurements")
    def list(self, limit: int | None = 20, *, since: float | None = None, until: float | None = None,
             status: str | None = None, full: bool = False, part_id: str | None = None,
             recipe: str | None = None, parts_only: bool = False) -> list[StoredMeasurement]:
        """Measurements, newest first (limit None: all). part_id / recipe: only those;
        parts_only: only the releases that completed a part (they carry the part verdict)."""
        where, args = _where(since=since, until=until, status=status, part_id=part_id, recipe=recipe,
                             parts_only=parts_only)
        lim = "LIMIT ?" if limit is not None else ""
        if limit is not None:
            args.append(int(limit))
        cols = _select(_columns("full" if full else "list"))
        with self._lock:
            rows = self._db.execute(f"SELECT {cols} FROM measurements {where} ORDER BY seq DESC {lim}", args).fetchall()
        return [self._row(r, full=full, trace=False) for r in rows]

    def recipes(self) -> builtins.list[str]:
        """Names of the recipes of the completed parts in the store, in order of first use."""
        with self._lock:
            rows = self._db.execute("SELECT recipe FROM measurements WHERE part_verdict IS NOT NULL "
                                    "GROUP BY recipe ORDER BY MIN(seq)").fetchall()
        return [r[0] for r in rows if r[0] is not None]

    @_store_errors("counting verdicts")
    def verdict_counts(self, since: float | None = None) -> dict[str, int]:
        """Completed parts by verdict (OK, NOK, INVALID) finished at or after ``since`` (Unix s)."""
        where, args = _where(since=since, parts_only=True)
        with self._lock:
            rows = self._db.execute(f"SELECT part_verdict, COUNT(*) FROM measurements {where} GROUP BY part_verdict",
                                    args).fetchall()
        return {"OK": 0, "NOK": 0, "INVALID": 0} | {str(v): int(n) for v, n in rows}

    @_store_errors("counting measurements")
    def count(self) -> int:
        with self._lock:
            return int(self._db.execute("SELECT COUNT(*) FROM measurements").fetchone()[0])

    # --- attachments (files kept with a measurement, e.g. its plot) ---------------
    def put_attachment(self, uuid: str, name: str, data: bytes, media_type: str) -> None:
        """Keep ``data`` with the measurement ``uuid`` under ``name`` (replaces one of the same name)."""
        try:
            with self._lock, self._tx() as db:
                db.execute("INSERT OR REPLACE INTO attachments (uuid, name, media_type, data, created_at) "
                           "VALUES (?,?,?,?,?)", (uuid, name, media_type, sqlite3.Binary(data), time.time()))
        except sqlite3.Error as exc:
            if _is_damage(exc):
                self.damage = f"{exc} while storing {name!r} of measurement {uuid}"
                raise StoreDamaged(f"the result store {str(self.path)!r} is damaged ({exc}): cannot store {name!r} "
                                   f"of measurement {uuid}") from None
            raise StoreError(f"cannot store {name!r} of measurement {uuid}: {exc}") from None

    # --- tensor sets --------------------------------------------------------------
    @_store_errors("storing a tensor set")
    def record_tensor_set(self, record: Mapping[str, Any], *, started_at: float | None, finished_at: float) -> None:
        """Store a finished tensor set (``TensorSet.to_dict()``): complete, aborted or failed."""
        tensor = record.get("tensor") or {}
        with self._lock, self._tx() as db:
            db.execute("INSERT INTO tensor_sets (uuid, status, recipe, part_id, started_at, finished_at, flags, "
                       "releases, record) VALUES (?,?,?,?,?,?,?,?,?)",
                       (record["uuid"], record["status"], record.get("recipe"), record.get("part_id"), started_at,
                        finished_at, json.dumps(tensor.get("flags") or []), json.dumps(record.get("releases") or {}),
                        json.dumps(record, allow_nan=False)))

    @_store_errors("reading tensor sets")
    def tensor_sets(self, limit: int | None = 20) -> builtins.list[dict[str, Any]]:
        """Stored tensor sets, newest first: their records with ``finished_at`` and ``started_at``."""
        with self._lock:
            if not self._db.execute("SELECT 1 FROM sqlite_master WHERE name = 'tensor_sets'").fetchone():
                return []  # a read-only store written before tensor sets existed
            rows = self._db.execute("SELECT record, started_at, finished_at FROM tensor_sets ORDER BY id DESC"
                                    + (" LIMIT ?" if limit is not None else ""),
                                    (int(limit),) if limit is not None else ()).fetchall()
        return [json.loads(r[0]) | {"started_at": r[1], "finished_at": r[2]} for r in rows]

    # --- check standards ----------------------------------------------------------
    @_store_errors("storing a check standard")
    def record_check_standard(self, record: Mapping[str, Any], *, finished_at: float) -> None:
        """Store one check-standard measurement (``CheckStandard.to_dict()`` and what it was measured with)."""
        with self._lock, self._tx() as db:
            db.execute("INSERT INTO check_standards (name, finished_at, passed, record) VALUES (?,?,?,?)",
                       (str(record["name"]), finished_at, 1 if record["passed"] else 0,
                        json.dumps(record, allow_nan=False)))

    @_store_errors("reading check standards")
    def check_standards(self, limit: int | None = 20) -> builtins.list[dict[str, Any]]:
        """Stored check-standard measurements, newest first, each with ``finished_at``."""
        with self._lock:
            if not self._db.execute("SELECT 1 FROM sqlite_master WHERE name = 'check_standards'").fetchone():
                return []  # a read-only store written before check standards existed
            rows = self._db.execute("SELECT record, finished_at FROM check_standards ORDER BY id DESC"
                                    + (" LIMIT ?" if limit is not None else ""),
                                    (int(limit),) if limit is not None else ()).fetchall()
        return [json.loads(r[0]) | {"finished_at": r[1]} for r in rows]

    @_store_errors("reading an attachment")
    def get_attachment(self, uuid: str, name: str) -> tuple[bytes, str] | None:
        """(data, media type) of an attachment, or None."""
        with self._lock:
            row = self._db.execute("SELECT data, media_type FROM attachments WHERE uuid = ? AND name = ?",
                                   (uuid, name)).fetchone()
        return (bytes(row[0]), row[1]) if row else None

    @_store_errors("searching measurements")
    def search(self, *, offset: int = 0, limit: int | None = 25, since: float | None = None,
               until: float | None = None, status: str | None = None, flag: str | None = None,
               part_id: str | None = None, recipe: str | None = None) -> tuple[builtins.list[StoredMeasurement], int]:
        """One page of measurements (with payloads), newest first, and how many match in all.
        The filters of ``list``, and flag: only those carrying this quality flag."""
        where, args = _where(since=since, until=until, status=status, part_id=part_id, recipe=recipe, flag=flag)
        with self._lock:
            total = int(self._db.execute(f"SELECT COUNT(*) FROM measurements {where}", args).fetchone()[0])
            page = f"LIMIT {int(limit)} OFFSET {int(offset)}" if limit is not None else ""
            rows = self._db.execute(f"SELECT {_select(_columns('full'))} FROM measurements {where} ORDER BY seq DESC {page}",
                                    args).fetchall()
        return [self._row(r, full=True, trace=False) for r in rows], total


def _where(*, since: float | None = None, until: float | None = None, status: str | None = None,
           part_id: str | None = None, recipe: str | None = None, parts_only: bool = False,
           flag: str | None = None) -> tuple[str, list[Any]]:
    """The WHERE clause (and its arguments) of the measurement filters of ``Store.list`` and ``Store.search``."""
    clauses: list[str] = []
    args: list[Any] = []
    for sql, value in (("part_id = ?", part_id), ("recipe = ?", recipe), ("finished_at >= ?", since),
                       ("finished_at < ?", until), ("status = ?", status),
                       ("EXISTS (SELECT 1 FROM json_each(flags) WHERE value = ?)", flag)):
        if value is not None:
            clauses.append(sql)
            args.append(value)
    if parts_only:
        clauses.append("part_verdict IS NOT NULL")
    return ("WHERE " + " AND ".join(clauses)) if clauses else "", args


#: the last sequence number given, beside the database: it survives a damage that loses the database's own
SEQ_FLOOR_NAME = "last-seq"


def read_seq_floor(state_dir: str | Path) -> int:
    """The last sequence number given in ``state_dir`` by its copy beside the database (0: none)."""
    try:
        return int((Path(state_dir) / SEQ_FLOOR_NAME).read_text(encoding="ascii").strip() or 0)
    except (OSError, ValueError):
        return 0


def write_seq_floor(state_dir: str | Path, seq: int) -> None:
    """Keep ``seq`` as the last sequence number given (atomic replace; a failure only loses the copy)."""
    path = Path(state_dir) / SEQ_FLOOR_NAME
    tmp = path.with_name(SEQ_FLOOR_NAME + ".tmp")
    try:
        tmp.write_text(f"{seq}\n", encoding="ascii")
        os.replace(tmp, path)
    except OSError:
        pass  # the database keeps its own counter; this copy is for when the database is lost
