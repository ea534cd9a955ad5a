"""Tracker's data export (File > Export > Data): tab-separated, CRLF, optionally a line naming the mass
(``mass_B``) before the header ``t x y ...``, positions in the units of Tracker's calibration."""

from __future__ import annotations

from .registry import Format, Probe
from .table import table_reader


def _header(probe: Probe) -> list[str]:
    lines = [ln for ln in probe.head.splitlines()[:3] if ln.strip()]
    for ln in lines[:2]:
        cells = [c.strip() for c in ln.split("\t")]
        if len(cells) >= 3:
            return cells
    return []


def sniff(probe: Probe) -> bool:
    cells = _header(probe)
    return bool(cells) and cells[0].split("_")[0] == "t" and any(c.split("_")[0] in ("x", "y") for c in cells)


read = table_reader("tracker", "Tracker export")


FORMAT = Format(
    "tracker", "Tracker's data export (tab-separated t, x, y with the origin at the pivot; a mass line before "
               "the header is skipped): the angle from the pivot",
    "moi identify 8049.txt --rig string.toml", sniff, read)
