"""Any other table of samples: CSV or TSV, its delimiter and a decimal comma sniffed, a header or none
(then the columns are numbered and named with --time-col and --angle-col or --rate-col)."""

from __future__ import annotations

from .registry import Format, Probe
from .table import table_reader


def sniff(probe: Probe) -> bool:
    return bool(probe.head.strip())


FORMAT = Format(
    "table", "any CSV/TSV of samples (delimiter and decimal comma sniffed; a file without a header has its "
             "columns numbered): the columns by name or number with --time-col, --angle-col, --rate-col or --xy",
    "moi identify log.tsv --time-col 1 --rate-col 3 --deg --rig rig.toml", sniff, table_reader("table", "table"))
