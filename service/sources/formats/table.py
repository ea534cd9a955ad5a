"""A delimited text table as exports write it: delimiter and decimal comma sniffed (``csv.Sniffer``),
lines before the header that are not the table's (Tracker's mass line) set aside, a file without a
header known as such."""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from typing import Callable

import numpy as np

from service.errors import InputFileError

from .log import Column, Log
from .registry import Probe, whole_text

_NUMBER = re.compile(r"^\s*[-+]?(\d+([.,]\d*)?|[.,]\d+)([eE][-+]?\d+)?\s*$")
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d*,\d+([eE][-+]?\d+)?\s*$")
#: the lines the delimiter is sniffed from
SNIFF_LINES = 40


@dataclass(frozen=True)
class Dialect:
    delimiter: str
    decimal_comma: bool


def _cells(line: str, delimiter: str) -> list[str]:
    if delimiter == " ":
        return line.split()
    return next(csv.reader([line], delimiter=delimiter), [])


def _is_number(cell: str) -> bool:
    return bool(_NUMBER.match(cell)) or cell.strip().lower() in {"nan", "inf", "-inf"}


def sniff_dialect(lines: list[str]) -> Dialect:
    """The delimiter (csv.Sniffer's among comma, semicolon, tab and space, or the first of them that splits the
    last lines into rows of numbers of one width) and whether decimals use a comma."""
    tail = lines[-SNIFF_LINES:]
    try:
        sniffed = [csv.Sniffer().sniff("\n".join(tail), delimiters=",;\t").delimiter]
    except csv.Error:
        sniffed = []
    for delimiter in dict.fromkeys(sniffed + [";", "\t", ",", " "]):
        rows = [_cells(line, delimiter) for line in tail]
        widths = {len(r) for r in rows if _numeric_row(r, delimiter != ",")}
        if len(widths) == 1 and widths.pop() >= 2:
            break
    else:
        delimiter = sniffed[0] if sniffed else ","
    cells = [c for line in tail for c in _cells(line, delimiter) if c.strip()]
    decimal_comma = delimiter != "," and any(_DECIMAL_COMMA.match(c) for c in cells)
    return Dialect(delimiter, decimal_comma)


def _numeric_row(cells: list[str], comma: bool = True) -> bool:
    filled = [c for c in cells if c.strip()]
    return bool(filled) and all(_is_number(c) and (comma or "," not in c) for c in filled)


def _header_index(rows: list[list[str]]) -> int | None:
    """The row naming the columns: the last non-numeric row before the first numeric one with as many
    cells (None: the table starts with data)."""
    first = next((i for i, r in enumerate(rows) if _numeric_row(r)), None)
    if first is None:
        raise InputFileError("no rows of numbers; expected a table of samples")
    width = len(rows[first])
    for i in range(first - 1, -1, -1):
        if len(rows[i]) >= width:
            return i
    return None


def _to_float(cell: str, decimal_comma: bool) -> float:
    c = cell.strip()
    if not c:
        return float("nan")
    return float(c.replace(",", ".") if decimal_comma else c)


def parse_table(text: str, source: str, fmt: str) -> Log:
    """The table in ``text``: its header (or numbered columns when the first row is data) and numbers."""
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputFileError(f"{source}: the file is empty; expected a table of samples")
    dialect = sniff_dialect(lines)
    rows = [_cells(ln, dialect.delimiter) for ln in lines]
    try:
        head = _header_index(rows)
    except InputFileError as exc:
        raise InputFileError(f"{source}: {exc}") from None
    start = 0 if head is None else head + 1
    width = max(len(r) for r in rows[start:start + SNIFF_LINES])
    labels = rows[head][:width] if head is not None else [f"column {i + 1}" for i in range(width)]
    data = np.full((len(rows) - start, width), np.nan)
    for n, r in enumerate(rows[start:]):
        if not _numeric_row(r):
            raise InputFileError(f"{source}: line {start + n + 1} is not numbers ({dialect.delimiter!r}-separated: "
                                 f"{lines[start + n][:80]!r}); expected one sample per line")
        vals = [_to_float(c, dialect.decimal_comma) for c in r[:width]]
        data[n, :len(vals)] = vals
    notes = []
    if head:
        notes.append(f"{head} line(s) before the header set aside: {', '.join(ln[:40] for ln in lines[:head])}")
    if dialect.decimal_comma:
        notes.append("decimal comma")
    return Log(source, fmt, tuple(Column.parse(lb) for lb in labels), data, has_header=head is not None,
               notes=tuple(notes))


def first_cells(head: str) -> list[str]:
    """The non-empty cells of a file's first non-empty line (tab- or comma-separated): its header, if any."""
    first = next((ln for ln in head.splitlines() if ln.strip()), "")
    return [c.strip() for c in next(csv.reader([first], delimiter="\t" if "\t" in first else ","), []) if c.strip()]


def table_reader(fmt: str, what: str) -> Callable[[Probe], Log]:
    """A format's ``read``: the file as one table (``parse_table``), named ``fmt``."""
    def read(probe: Probe) -> Log:
        return parse_table(whole_text(probe, what), str(probe.path), fmt)

    return read
