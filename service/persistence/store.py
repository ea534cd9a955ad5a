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
import json
import sqlite3
import threading
import time
import uuid as uuidlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from service.core.vocabulary import operator_of
from service.errors import StoreDamaged, StoreError
from service.persistence.connection import is_damage, read_only_connection, store_errors
from service.persistence.sequence import next_seq, write_seq_floor
from service.persistence.tables import (
    COLUMNS,
    INSERT,
    INSERTED,
    Given,
    check_version,
    columns,
    create_tables,
    mark_version,
    select,
    unpack,
)

DB_NAME = "results.db"
#: the largest integer SQLite stores (a longer sequence number is no measurement's)
SQLITE_MAX_INTEGER = 2**63 - 1


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
    operator: str | None = None

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
            create_tables(self._db)
            with self._tx() as db:
                mark_version(db, self.path)
        except sqlite3.Error as exc:
            if is_damage(exc):
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
            if is_damage(exc):
                raise StoreDamaged(f"the result store {str(self.path)!r} is damaged ({exc})") from None
            raise StoreError(f"cannot read the result store {str(self.path)!r}: {exc}") from None
        check_version(self.path, row[0] if row is not None else None)
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
        operator: str | None = None,
    ) -> StoredMeasurement:
        """Store one measurement and queue its publications, atomically.

        build_payload(uuid, seq) makes the published payload once the sequence
        number is known (ok results). enqueue: the outbox kinds to queue per consumer (the publisher
        that delivers them, e.g. {"mqtt": ("result",)}); the payload is queued as it is stored, one row
        per consumer and kind, each acknowledged by its consumer alone. part: values of
        the schema-2 part columns (``COLUMNS`` with ``since=2``: part ID, recipe, verdicts...), missing keys are NULL.
        operator: who measured (``service.core.vocabulary.operator_of``); None: the one ``trigger`` says.
        """
        from service.persistence.canonical import dumps

        uid = uuid or str(uuidlib.uuid4())
        now = time.time()
        try:
            with self._lock, self._tx() as db:
                seq = next_seq(db, self.state_dir)
                payload = build_payload(uid, seq) if build_payload is not None else None
                payload_text = dumps(payload) if payload is not None else None
                given = Given(uid, seq, now, payload_text, dict(
                    status=status, trigger=trigger, device_id=device_id, software_version=software_version,
                    started_at=started_at, finished_at=finished_at, result=result, error=error, rig=rig,
                    config=config, trace_t=trace_t, trace_angle=trace_angle, trace_meta=trace_meta, part=part,
                    operator=operator))
                mid = db.execute(INSERT, [c.value(given) for c in INSERTED if c.value is not None]).lastrowid
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
    @store_errors("reading the outbox")
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

    @store_errors("updating the outbox")
    def outbox_attempt(self, item_id: int) -> None:
        with self._lock, self._tx() as db:
            db.execute("UPDATE outbox SET attempts = attempts + 1, last_attempt = ? WHERE id = ?", (time.time(), item_id))

    @store_errors("updating the outbox")
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

    @store_errors("counting the outbox")
    def outbox_count(self, consumer: str | None = None) -> int:
        """Rows not yet acknowledged: a consumer's, or everyone's."""
        where, args = (" WHERE consumer = ?", (consumer,)) if consumer is not None else ("", ())
        with self._lock:
            return int(self._db.execute(f"SELECT COUNT(*) FROM outbox{where}", args).fetchone()[0])

    # --- reading ------------------------------------------------------------------
    @staticmethod
    def _row(row: Sequence[Any], full: bool, trace: bool) -> StoredMeasurement:
        """A row selected with the columns of ``columns("full" if full else "list", trace=trace)``."""
        d: dict[str, Any] = {}
        for c, v in zip(columns("full" if full else "list", trace=trace), row, strict=True):
            if c.codec == "flags":
                v = tuple(json.loads(v or "[]"))
            elif c.codec == "json" and v is not None:
                v = json.loads(v)
            elif c.codec == "array":
                v = unpack(v)
            d[c.name] = v
        if d.get("operator") is None:  # stored only where the trigger does not say it (``tables._operator``)
            d["operator"] = operator_of(d["trigger"])
        return StoredMeasurement(**d)

    @store_errors("reading a measurement")
    def get(self, key: str | int, *, trace: bool = False) -> StoredMeasurement | None:
        """A measurement by UUID (or a unique UUID prefix) or by sequence number.

        A key of digits only is a sequence number first and a UUID prefix when no measurement has that
        number (a UUID may start with eight digits)."""
        cols = select(columns("full", trace=trace))
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

    @store_errors("reading a measurement")
    def has_trace(self, uuid: str) -> bool:
        """Whether the measurement ``uuid`` was stored with its trace (without reading the trace)."""
        with self._lock:
            row = self._db.execute("SELECT trace_t IS NOT NULL FROM measurements WHERE uuid = ?", (uuid,)).fetchone()
        return bool(row and row[0])

    @store_errors("reading the latest measurement")
    def latest(self, status: str | None = "ok") -> StoredMeasurement | None:
        where = "WHERE status = ?" if status else ""
        args: tuple = (status,) if status else ()
        with self._lock:
            row = self._db.execute(f"SELECT {select(columns('full'))} FROM measurements {where} "
                                   "ORDER BY seq DESC LIMIT 1", args).fetchone()
        return self._row(row, full=True, trace=False) if row else None

    @store_errors("listing measurements")
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
        cols = select(columns("full" if full else "list"))
        with self._lock:
            rows = self._db.execute(f"SELECT {cols} FROM measurements {where} ORDER BY seq DESC {lim}", args).fetchall()
        return [self._row(r, full=full, trace=False) for r in rows]

    def recipes(self) -> builtins.list[str]:
        """Names of the recipes of the completed parts in the store, in order of first use."""
        with self._lock:
            rows = self._db.execute("SELECT recipe FROM measurements WHERE part_verdict IS NOT NULL "
                                    "GROUP BY recipe ORDER BY MIN(seq)").fetchall()
        return [r[0] for r in rows if r[0] is not None]

    @store_errors("counting verdicts")
    def verdict_counts(self, since: float | None = None) -> dict[str, int]:
        """Completed parts by verdict (OK, NOK, INVALID) finished at or after ``since`` (Unix s)."""
        where, args = _where(since=since, parts_only=True)
        with self._lock:
            rows = self._db.execute(f"SELECT part_verdict, COUNT(*) FROM measurements {where} GROUP BY part_verdict",
                                    args).fetchall()
        return {"OK": 0, "NOK": 0, "INVALID": 0} | {str(v): int(n) for v, n in rows}

    @store_errors("counting measurements")
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
            if is_damage(exc):
                self.damage = f"{exc} while storing {name!r} of measurement {uuid}"
                raise StoreDamaged(f"the result store {str(self.path)!r} is damaged ({exc}): cannot store {name!r} "
                                   f"of measurement {uuid}") from None
            raise StoreError(f"cannot store {name!r} of measurement {uuid}: {exc}") from None

    # --- tensor sets --------------------------------------------------------------
    @store_errors("storing a tensor set")
    def record_tensor_set(self, record: Mapping[str, Any], *, started_at: float | None, finished_at: float) -> None:
        """Store a finished tensor set (``TensorSet.to_dict()``): complete, aborted or failed."""
        tensor = record.get("tensor") or {}
        with self._lock, self._tx() as db:
            db.execute("INSERT INTO tensor_sets (uuid, status, recipe, part_id, started_at, finished_at, flags, "
                       "releases, record) VALUES (?,?,?,?,?,?,?,?,?)",
                       (record["uuid"], record["status"], record.get("recipe"), record.get("part_id"), started_at,
                        finished_at, json.dumps(tensor.get("flags") or []), json.dumps(record.get("releases") or {}),
                        json.dumps(record, allow_nan=False)))

    @store_errors("reading tensor sets")
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
    @store_errors("storing a check standard")
    def record_check_standard(self, record: Mapping[str, Any], *, finished_at: float) -> None:
        """Store one check-standard measurement (``CheckStandard.to_dict()`` and what it was measured with)."""
        with self._lock, self._tx() as db:
            db.execute("INSERT INTO check_standards (name, finished_at, passed, record) VALUES (?,?,?,?)",
                       (str(record["name"]), finished_at, 1 if record["passed"] else 0,
                        json.dumps(record, allow_nan=False)))

    @store_errors("reading check standards")
    def check_standards(self, limit: int | None = 20) -> builtins.list[dict[str, Any]]:
        """Stored check-standard measurements, newest first, each with ``finished_at``."""
        with self._lock:
            if not self._db.execute("SELECT 1 FROM sqlite_master WHERE name = 'check_standards'").fetchone():
                return []  # a read-only store written before check standards existed
            rows = self._db.execute("SELECT record, finished_at FROM check_standards ORDER BY id DESC"
                                    + (" LIMIT ?" if limit is not None else ""),
                                    (int(limit),) if limit is not None else ()).fetchall()
        return [json.loads(r[0]) | {"finished_at": r[1]} for r in rows]

    # --- gauge studies ------------------------------------------------------------
    @store_errors("storing a gauge study")
    def record_gauge_study(self, record: Mapping[str, Any], *, started_at: float | None, finished_at: float) -> None:
        """Store a finished gauge study (``Type1Record.to_dict()``): complete, aborted or failed."""
        with self._lock, self._tx() as db:
            db.execute("INSERT INTO gauge_studies (uuid, kind, status, recipe, started_at, finished_at, releases, "
                       "record) VALUES (?,?,?,?,?,?,?,?)",
                       (record["uuid"], record["kind"], record["status"], record.get("recipe"), started_at,
                        finished_at, json.dumps(record.get("releases") or []), json.dumps(record, allow_nan=False)))

    @store_errors("reading gauge studies")
    def gauge_studies(self, kind: str, *, recipe: str | None = None, status: str | None = None,
                      uuid: str | None = None, limit: int | None = 20) -> builtins.list[dict[str, Any]]:
        """Stored gauge studies of ``kind``, newest first (of ``recipe``, with ``status``, the one ``uuid``
        when given): their records with ``started_at`` and ``finished_at``."""
        where, args = ["kind = ?"], [kind]
        for column, value in (("recipe", recipe), ("status", status), ("uuid", uuid)):
            if value is not None:
                where.append(f"{column} = ?")
                args.append(value)
        with self._lock:
            if not self._db.execute("SELECT 1 FROM sqlite_master WHERE name = 'gauge_studies'").fetchone():
                return []  # a read-only store written before gauge studies existed
            rows = self._db.execute("SELECT record, started_at, finished_at FROM gauge_studies WHERE "
                                    + " AND ".join(where) + " ORDER BY id DESC"
                                    + (f" LIMIT {int(limit)}" if limit is not None else ""), args).fetchall()
        return [json.loads(r[0]) | {"started_at": r[1], "finished_at": r[2]} for r in rows]

    @store_errors("reading an attachment")
    def get_attachment(self, uuid: str, name: str) -> tuple[bytes, str] | None:
        """(data, media type) of an attachment, or None."""
        with self._lock:
            row = self._db.execute("SELECT data, media_type FROM attachments WHERE uuid = ? AND name = ?",
                                   (uuid, name)).fetchone()
        return (bytes(row[0]), row[1]) if row else None

    @store_errors("searching measurements")
    def search(self, *, offset: int = 0, limit: int | None = 25, since: float | None = None,
               until: float | None = None, status: str | None = None, flag: str | None = None,
               part_id: str | None = None, recipe: str | None = None) -> tuple[builtins.list[StoredMeasurement], int]:
        """One page of measurements (with payloads), newest first, and how many match in all.
        The filters of ``list``, and flag: only those carrying this quality flag."""
        where, args = _where(since=since, until=until, status=status, part_id=part_id, recipe=recipe, flag=flag)
        with self._lock:
            total = int(self._db.execute(f"SELECT COUNT(*) FROM measurements {where}", args).fetchone()[0])
            page = f"LIMIT {int(limit)} OFFSET {int(offset)}" if limit is not None else ""
            rows = self._db.execute(f"SELECT {select(columns('full'))} FROM measurements {where} ORDER BY seq DESC {page}",
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
