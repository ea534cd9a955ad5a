"""Any other table of samples: CSV or TSV, its delimiter and a decimal comma sniffed, a header or none
(then the columns are numbered and named with --time-col and --angle-col or --rate-col)."""

from __future__ import annotations

from .log import Log
from .registry import Format, Probe, whole_text
from .table import parse_table


def sniff(probe: Probe) -> bool:
    return bool(probe.head.strip())


def read(probe: Probe) -> Log:
    return parse_table(whole_text(probe, "table"), str(probe.path), "table")


FORMAT = Format(
    "table", "any CSV/TSV of samples (delimiter and decimal comma sniffed; a file without a header has its "
             "columns numbered): the columns by name or number with --time-col, --angle-col, --rate-col or --xy",
    "moi identify log.tsv --time-col 1 --rate-col 3 --deg --rig rig.toml", sniff, read)
