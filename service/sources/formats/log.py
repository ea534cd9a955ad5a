"""What a reader gives: a ``Log``, the columns of one export with their names, units and events."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

#: "Run 1: Angle (°)", "Latest: Time (s)", "Angle (rad) Run #2", "Gyroscope x (rad/s)", "x_{1}", "theta [deg]"
_LABEL = re.compile(r"^(?:(?P<set>[^:()\[\]]+):\s*)?(?P<name>.*?)\s*(?:\((?P<unit>[^()]*)\)|\[(?P<unit2>[^\[\]]*)\])?"
                    r"\s*(?P<run>Run\s*#?\s*\d+)?\s*$", re.IGNORECASE)


@dataclass(frozen=True)
class Column:
    """One column: its label as the file gives it, the quantity's name, its unit ('' when not stated)
    and the data set or run it belongs to ('' for a file with one)."""

    label: str
    name: str
    unit: str = ""
    group: str = ""

    @classmethod
    def parse(cls, label: str) -> Column:
        m = _LABEL.match(label.strip())
        if m is None:  # the pattern matches any text; kept for the type checker
            return cls(label.strip(), label.strip())
        group = (m.group("set") or m.group("run") or "").strip()
        return cls(label.strip(), m.group("name").strip(), (m.group("unit") or m.group("unit2") or "").strip(), group)


@dataclass(frozen=True, eq=False)
class Log:
    """An export read as it came.

    source: the file; format: the reader's name; columns and data (one row per sample, NaN where a
    cell was empty, as in a logger's run shorter than the others); events: (what, time in s) where
    the recording was started or paused (phyphox: its clock stops while paused); has_header: the
    file named its columns (False: the first row was data, and the columns are numbered);
    notes: what the reader learnt (a mass line before the header, a decimal comma).
    """

    source: str
    format: str
    columns: tuple[Column, ...]
    data: np.ndarray
    events: tuple[tuple[str, float], ...] = ()
    has_header: bool = True
    notes: tuple[str, ...] = field(default=())

    def column(self, i: int) -> np.ndarray:
        return self.data[:, i]
