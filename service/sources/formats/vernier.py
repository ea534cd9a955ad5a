"""Logger Pro's and Vernier Graphical Analysis' CSV export: every column named "Data set: Quantity (unit)"
("Latest: Time (s)", "Run 1: Angle (°)", "VideoAnalysis: X (m)"); several runs side by side."""

from __future__ import annotations

import csv
import re

from .log import Log
from .registry import Format, Probe, whole_text
from .table import parse_table

_CELL = re.compile(r"^[^:]+:\s*\S.*\(.*\)$")


def sniff(probe: Probe) -> bool:
    first = next((ln for ln in probe.head.splitlines() if ln.strip()), "")
    cells = [c.strip() for c in next(csv.reader([first], delimiter="\t" if "\t" in first else ","), []) if c.strip()]
    return len(cells) >= 2 and all(_CELL.match(c) for c in cells)


def read(probe: Probe) -> Log:
    log = parse_table(whole_text(probe, "Logger Pro export"), str(probe.path), "logger-pro")
    return Log(log.source, "logger-pro", log.columns, log.data, (), log.has_header, log.notes)


FORMAT = Format(
    "logger-pro", "Logger Pro / Graphical Analysis CSV (\"Run 1: Time (s)\", \"Run 1: Angle (°)\" ...; each run a "
                  "release)", "moi identify pendulum.csv --rig rig.toml", sniff, read)
