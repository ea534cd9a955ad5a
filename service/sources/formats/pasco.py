"""PASCO Capstone's CSV export: columns named "Quantity (unit) Run #n" ("Time (s) Run #1",
"Angle (rad) Run #1"); several runs side by side, the shorter ones padded with empty cells."""

from __future__ import annotations

import re

from .registry import Format, Probe
from .table import first_cells, table_reader

_CELL = re.compile(r"Run\s*#\s*\d+\s*$", re.IGNORECASE)


def sniff(probe: Probe) -> bool:
    cells = first_cells(probe.head)
    return len(cells) >= 2 and all(_CELL.search(c) for c in cells)


FORMAT = Format(
    "capstone", "PASCO Capstone CSV (\"Time (s) Run #1\", \"Angle (rad) Run #1\" ...; each run a release)",
    "moi identify capstone.csv --rig rig.toml", sniff, table_reader("capstone", "Capstone export"))
