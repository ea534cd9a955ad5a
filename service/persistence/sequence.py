"""The measurements' sequence numbers are never reused: the last one given is also kept in a file beside the
database, which survives a damage that loses the database's own counter."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

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


def next_seq(db: sqlite3.Connection, state_dir: str | Path) -> int:
    """Draw the next sequence number (in the caller's write transaction): above every stored one, the
    database's counter and the copy beside it, so a number is never reused, even after rows were pruned."""
    seq = int(db.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM measurements").fetchone()[0])
    counter = db.execute("SELECT value FROM meta WHERE key='last_seq'").fetchone()
    if counter is not None:
        seq = max(seq, int(counter[0]) + 1)
    seq = max(seq, read_seq_floor(state_dir) + 1)
    db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES ('last_seq', ?)", (str(seq),))
    return seq
