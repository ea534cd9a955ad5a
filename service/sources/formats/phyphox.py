"""phyphox's CSV export: a folder or its zip holding the data table(s) and ``meta/`` (``time.csv``: the
START/PAUSE events, the clock stopping while paused; ``device.csv``), or the data table alone."""

from __future__ import annotations

import csv

from service.errors import InputFileError

from .log import Log
from .registry import Format, Probe, member_text
from .table import parse_table

TIME_CSV = "meta/time.csv"


def _prefix(probe: Probe) -> str | None:
    """The folder inside the zip or folder that holds meta/time.csv ('' at the top; None: none)."""
    for m in probe.members:
        if m == TIME_CSV or m.endswith("/" + TIME_CSV):
            return m[:-len(TIME_CSV)]
    return None


def sniff(probe: Probe) -> bool:
    return _prefix(probe) is not None


def _events(text: str) -> tuple[tuple[str, float], ...]:
    """(event, experiment time in s) of meta/time.csv."""
    rows = list(csv.reader(text.splitlines()))
    if not rows or [c.strip().lower() for c in rows[0][:2]] != ["event", "experiment time"]:
        raise InputFileError(f"{TIME_CSV}: expected the columns \"event\", \"experiment time\"")
    out = []
    for r in rows[1:]:
        if len(r) >= 2 and r[0].strip():
            try:
                out.append((r[0].strip().upper(), float(r[1])))
            except ValueError:
                raise InputFileError(f"{TIME_CSV}: {r[1]!r} is not a time in s") from None
    return tuple(out)


def read(probe: Probe) -> Log:
    prefix = _prefix(probe) or ""
    tables = [m for m in probe.members if m.startswith(prefix) and m.lower().endswith(".csv")
              and not m[len(prefix):].startswith("meta/")]
    if not tables:
        raise InputFileError(f"{str(probe.path)!r}: a phyphox export without a data table (only meta/); "
                             "expected the CSV phyphox writes beside meta/")
    # several views export several tables; the raw sensor data's is the one a swing is in
    tables.sort(key=lambda m: (not m.endswith("Raw Data.csv"), m))
    log = parse_table(member_text(probe, tables[0], "phyphox table"), f"{probe.path}/{tables[0][len(prefix):]}",
                      "phyphox")
    events = _events(member_text(probe, prefix + TIME_CSV, "phyphox events"))
    notes = log.notes + ((f"other tables not read: {', '.join(tables[1:])}",) if len(tables) > 1 else ())
    return Log(str(probe.path), "phyphox", log.columns, log.data, events, log.has_header, notes)


FORMAT = Format(
    "phyphox", "phyphox's CSV export (a folder or its zip with meta/time.csv; its START/PAUSE events split "
               "the log); a gyroscope's three axes are reduced to the swing's own",
    "moi identify 'Gyroscope rotation rate 2025-03-07 14-02-08.zip' --rig racquet.toml",
    sniff, read)
