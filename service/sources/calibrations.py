"""A rig's calibration history: every calibration `moi calibrate --out RIG.toml` made, appended beside the rig file.

The rig file holds the calibration in force (``[calibration]``, k and I0 with their 1σ); the history holds every
one, oldest first, as an instrument's calibration record does: ``RIG.calibrations.jsonl`` in the rig file's
folder (``torsion_rig.toml`` → ``torsion_rig.calibrations.jsonl``). JSON Lines, one calibration a line, only ever
appended (and flushed to the disk before `moi calibrate` reports success), never rewritten: a line is the fact
of one calibration, and nothing else holds it. A line that cannot be read (cut short by a power loss, edited by
hand, a name with a control character in it) is said by the byte it starts at; the others stay readable.

The file is read from its end, a page at a time (the newest lines, then the ones before the oldest shown):
however long the history has grown, a page costs the page's lines, not the file.

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
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, BinaryIO, Mapping

from service.errors import InputFileError
from service.names import name_problem

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


#: a line longer than this is no calibration: said damaged, never held in memory whole
MAX_LINE = 64 * 1024

#: bytes read at a time, from the end backwards
_BLOCK = 64 * 1024


@dataclass(frozen=True)
class History:
    """A page of a rig's history as read from the end of its file: ``entries`` newest first (each with its
    ``offset``, the byte its line starts at), ``damaged``: one sentence per line of the page that is not a
    calibration, or for a file that cannot be read; ``older``: the offset to read the next (older) page before,
    None when the page reaches the file's first line."""

    path: Path
    entries: list[dict[str, Any]] = field(default_factory=list)
    damaged: list[str] = field(default_factory=list)
    older: int | None = None


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
    return names_problem(doc)


def names_problem(entry: Mapping[str, Any]) -> str | None:
    """Why the names of a calibration (who ran it, its references' names and certificates) break the names rule,
    or None: a history line or a rig file's ``[calibration]`` edited by hand reaches the page and the terminal."""
    if entry.get("by") is not None and (problem := name_problem("person", entry["by"])) is not None:
        return problem
    references = entry.get("references") or []
    if not isinstance(references, list) or not all(isinstance(r, Mapping) for r in references):
        return "references is not a list of tables"
    for ref in references:
        for key, kind in (("name", "reference"), ("certificate", "certificate")):
            if ref.get(key) is not None and (problem := name_problem(kind, ref[key])) is not None:
                return problem
    return None


def recorded_at(entry: Mapping[str, Any]) -> float:
    """When the calibration was written, Unix s (ValueError when the line's ``recorded_at`` is not a time)."""
    t = dt.datetime.fromisoformat(str(entry["recorded_at"]).replace("Z", "+00:00"))
    if t.tzinfo is None:
        raise ValueError(f"recorded_at {entry['recorded_at']!r} has no UTC offset")
    return t.timestamp()


def _lines_before(f: BinaryIO, end: int) -> Iterator[tuple[int, bytes | None]]:
    """The lines of ``f`` that end before byte ``end``, newest first, read backwards a block at a time: (the
    byte the line starts at, its bytes; None for a line longer than MAX_LINE, which is skipped, not held)."""
    pos, tail, overlong = end, b"", False
    while pos > 0:
        size = min(_BLOCK, pos)
        pos -= size
        f.seek(pos)
        block = f.read(size)
        right = len(block)
        while (nl := block.rfind(b"\n", 0, right)) != -1:
            piece = block[nl + 1:right]
            yield pos + nl + 1, None if overlong or len(piece) + len(tail) > MAX_LINE else piece + tail
            tail, overlong, right = b"", False, nl
        if not overlong:
            overlong = right + len(tail) > MAX_LINE
            tail = b"" if overlong else block[:right] + tail
    if tail or overlong:
        yield 0, None if overlong else tail


def _entry(raw: bytes | None) -> tuple[dict[str, Any] | None, str]:
    """A line read as a calibration, or None and why not."""
    if raw is None:
        return None, f"longer than {MAX_LINE // 1024} KiB"
    try:
        doc = json.loads(raw.decode("utf-8", errors="replace"))
    except json.JSONDecodeError as exc:
        return None, f"not JSON: {exc.msg}"
    problem = _problem(doc)
    return (doc, "") if problem is None else (None, problem)


def read_history(rig_path: str | os.PathLike, limit: int | None, before: int | None = None) -> History:
    """A page of the history of the rig file ``rig_path``, newest first: the ``limit`` lines (None: all) that end
    before byte ``before`` (None: the end of the file). Memory and time grow with the page, not the file (bar a
    line too long to be a calibration, skipped a block at a time). Empty when no history was written yet."""
    path = history_path(rig_path)
    history = History(path)
    try:
        with open(path, "rb") as f:
            end = os.fstat(f.fileno()).st_size
            end = end if before is None else max(0, min(before, end))
            lines, oldest = 0, end
            for start, raw in _lines_before(f, end):
                if raw is not None and not raw.strip():
                    continue
                if limit is not None and lines == limit:  # an older line: the next page reads before this one's
                    return replace(history, older=oldest)
                lines, oldest = lines + 1, start
                doc, why = _entry(raw)
                if doc is None:
                    history.damaged.append(f"the line at byte {start} of {path.name} is damaged ({why}); left out")
                else:
                    history.entries.append(doc | {"offset": start})
    except FileNotFoundError:
        return history
    except OSError as exc:
        return History(path, damaged=[f"{path.name} cannot be read: {exc.strerror or exc}"])
    return history
