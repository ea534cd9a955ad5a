"""A guided run's record on disk while it runs (a tensor set, a Type 1 study): written at each step, so that a run
cut short by a kill is found at the next start and stored as interrupted; removed once the run is stored."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any, Mapping

log = logging.getLogger("moi.parts")


class RunningRecord:
    """``path``: the record's file in the state directory; ``what``: the run's name in the log ("tensor set")."""

    def __init__(self, path: Path, what: str) -> None:
        self.path, self.what = path, what

    def keep(self, record: Mapping[str, Any]) -> None:
        """The record written whole (a reader never sees half of it); a failure is said and the run goes on: only a
        kill would then leave it unrecorded."""
        from service.sources.files import write_text_atomic

        try:
            write_text_atomic(self.path, json.dumps(record, allow_nan=False))
        except (OSError, ValueError) as exc:
            log.warning("cannot keep the running %s in %s: %s", self.what, self.path, exc)

    def drop(self) -> None:
        self.path.unlink(missing_ok=True)

    def read(self) -> dict[str, Any] | None:
        """The running record as kept (None: none runs, or it cannot be read)."""
        try:
            record = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return record if isinstance(record, dict) and isinstance(record.get("uuid"), str) else None

    def left(self) -> dict[str, Any] | None:
        """The record a run the last daemon left unfinished (a kill), or None; a damaged file is said and removed."""
        if not self.path.exists():
            return None
        record = self.read()
        if record is None:
            self.damaged("not a record")
        return record

    def damaged(self, why: object) -> None:
        """The kept record cannot be read back: said, and removed (a new run starts)."""
        log.warning("the running %s's file %s is damaged (%s); removed", self.what, self.path, why)
        self.drop()
