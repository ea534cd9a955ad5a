"""PASCO Capstone's CSV export: columns named "Quantity (unit) Run #n" ("Time (s) Run #1",
"Angle (rad) Run #1"); several runs side by side, the shorter ones padded with empty cells."""

from __future__ import annotations

import csv
import re

from .log import Log
from .registry import Format, Probe, whole_text
from .table import parse_table

_CELL = re.compile(r"Run\s*#\s*\d+\s*$", re.IGNORECASE)


def sniff(probe: Probe) -> bool:
    first = next((ln for ln in probe.head.splitlines() if ln.strip()), "")
    cells = [c.strip() for c in next(csv.reader([first], delimiter="\t" if "\t" in first else ","), []) if c.strip()]
    return len(cells) >= 2 and all(_CELL.search(c) for c in cells)


def read(probe: Probe) -> Log:
    log = parse_table(whole_text(probe, "Capstone export"), str(probe.path), "capstone")
    return Log(log.source, "capstone", log.columns, log.data, (), log.has_header, log.notes)


FORMAT = Format(
    "capstone", "PASCO Capstone CSV (\"Time (s) Run #1\", \"Angle (rad) Run #1\" ...; each run a release)",
    "moi identify capstone.csv --rig rig.toml", sniff, read)
