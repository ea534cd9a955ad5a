"""Logger Pro's and Vernier Graphical Analysis' CSV export: every column named "Data set: Quantity (unit)"
("Latest: Time (s)", "Run 1: Angle (°)", "VideoAnalysis: X (m)"); several runs side by side."""

from __future__ import annotations

import re

from .registry import Format, Probe
from .table import first_cells, table_reader

_CELL = re.compile(r"^[^:]+:\s*\S.*\(.*\)$")


def sniff(probe: Probe) -> bool:
    cells = first_cells(probe.head)
    return len(cells) >= 2 and all(_CELL.match(c) for c in cells)


FORMAT = Format(
    "logger-pro", "Logger Pro / Graphical Analysis CSV (\"Run 1: Time (s)\", \"Run 1: Angle (°)\" ...; each run a "
                  "release)", "moi identify pendulum.csv --rig rig.toml", sniff,
    table_reader("logger-pro", "Logger Pro export"))
