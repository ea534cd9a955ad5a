"""A rig's calibration history: every calibration `moi calibrate --out RIG.toml` made, appended beside the rig file.

The rig file holds the calibration in force (``[calibration]``, k and I0 with their 1σ); the history holds every
one, oldest first, as an instrument's calibration record does: ``RIG.calibrations.jsonl`` in the rig file's
folder (``torsion_rig.toml`` → ``torsion_rig.calibrations.jsonl``). JSON Lines, one calibration a line, only ever
appended (and flushed to the disk before `moi calibrate` reports success), never rewritten: a line is the fact
of one calibration, and nothing else holds it. A line that cannot be read (cut short by a power loss, edited by
hand) is said by its number; the others stay readable.

Each line: ``date`` (the calibration's, YYYY-MM-DD), ``valid_days`` and ``valid_until``, ``recorded_at`` (when
it was written, ISO 8601 UTC), ``by`` (who ran it: ``--by``, else the login name), ``host``, ``software``,
``stiffness`` and ``stiffness_std`` (N·m/rad), ``tare_inertia`` and ``tare_inertia_std`` (kg·m²),
``stiffness_tare_covariance``, ``references`` (each with its name, added inertia and 1σ in kg·m², its
``certificate`` when CAL.toml names one, ω_n and 1σ in rad/s), ``calibration_file`` (CAL.toml), ``rig_file`` (the
rig file written) and ``from_rig`` (the rig file it started from).
"""

from __future__ import annotations

import datetime as dt
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from service.errors import InputFileError

#: the history file beside RIG.toml: RIG + this
SUFFIX = ".calibrations.jsonl"

#: what a line must hold to be a calibration
REQUIRED = ("date", "recorded_at", "stiffness")


def history_path(rig_path: str | os.PathLike) -> Path:
    """The history file of the rig file ``rig_path``."""
    p = Path(rig_path)
    return p.with_name(p.stem + SUFFIX)


def append(rig_path: str | os.PathLike, entry: Mapping[str, Any]) -> Path:
    """Append ``entry`` (one calibration, JSON-serialisable, finite numbers) to the history of ``rig_path``; on the
    disk when this returns. InputFileError when it cannot be written."""
    path = history_path(rig_path)
    line = json.dumps(dict(entry), ensure_ascii=False, allow_nan=False, sort_keys=False) + "\n"
    new = not path.exists()
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
        if new:  # the file's name in its folder survives a power loss too
            fd = os.open(path.parent, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
    except OSError as exc:
        raise InputFileError(f"calibration history {str(path)!r} cannot be written: {exc.strerror or exc}") from None
    return path


@dataclass(frozen=True)
class History:
    """A rig's history as read: ``entries`` oldest first (each with its ``line`` number), ``damaged``: one sentence
    per line that is not a calibration, or for a file that cannot be read."""

    path: Path
    entries: list[dict[str, Any]] = field(default_factory=list)
    damaged: list[str] = field(default_factory=list)

    @property
    def newest_first(self) -> list[dict[str, Any]]:
        return self.entries[::-1]


def _problem(doc: Any) -> str | None:
    """Why a line's JSON is not a calibration (None: it is one)."""
    if not isinstance(doc, dict):
        return f"a {type(doc).__name__}, not a calibration"
    missing = [k for k in REQUIRED if k not in doc]
    if missing:
        return f"no {', '.join(missing)}"
    try:
        dt.date.fromisoformat(str(doc["date"]))
        recorded_at(doc)
    except ValueError as exc:
        return str(exc)
    k = doc["stiffness"]
    if isinstance(k, bool) or not isinstance(k, (int, float)) or not math.isfinite(k):
        return f"stiffness {k!r} is not a number"
    return None


def recorded_at(entry: Mapping[str, Any]) -> float:
    """When the calibration was written, Unix s (ValueError when the line's ``recorded_at`` is not a time)."""
    t = dt.datetime.fromisoformat(str(entry["recorded_at"]).replace("Z", "+00:00"))
    if t.tzinfo is None:
        raise ValueError(f"recorded_at {entry['recorded_at']!r} has no UTC offset")
    return t.timestamp()


def read_history(rig_path: str | os.PathLike) -> History:
    """The history of the rig file ``rig_path`` (empty when none was written yet)."""
    path = history_path(rig_path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return History(path)
    except OSError as exc:
        return History(path, damaged=[f"{path.name} cannot be read: {exc.strerror or exc}"])
    history = History(path)
    for n, raw in enumerate(text.splitlines(), start=1):
        if not raw.strip():
            continue
        try:
            doc = json.loads(raw)
        except json.JSONDecodeError as exc:
            history.damaged.append(f"line {n} of {path.name} is damaged (not JSON: {exc.msg}); left out")
            continue
        problem = _problem(doc)
        if problem is not None:
            history.damaged.append(f"line {n} of {path.name} is damaged ({problem}); left out")
            continue
        history.entries.append(doc | {"line": n})
    return history
