"""`moi export`: write stored measurements as CSV (one row each), JSON (full payloads) or AQDEF/Q-DAS DFQ
(a recipe's parts, for SPC systems), or one raw trace.

Values are SI (kg·m², rad/s, rad; the CSV's ``unit`` column and the JSON's ``unit`` key say the unit of
inertia); every time is ISO 8601 with its offset (UTC), e.g. 2025-01-31T12:00:00.123+00:00."""

from __future__ import annotations

import argparse
import sys

from service.errors import InputFileError
from service.publish.export import csv_text, dfq_bytes, json_text, trace_text
from service.sources.files import write_atomic, write_text_atomic

from ._common import add_store_arguments, open_store, parse_time


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_store_arguments(p)
    p.add_argument("--format", "-f", choices=("csv", "json", "dfq"), default="csv",
                   help="output format (default csv; dfq: AQDEF/Q-DAS file of one recipe's parts)")
    p.add_argument("--recipe", "-r", metavar="NAME", help="only this recipe's measurements (dfq: the recipe; "
                   "needed when the store holds parts of several)")
    p.add_argument("--unit", metavar="UNIT", help="dfq: unit of the values (default: the recipe's display unit, "
                   "else kg·m²)")
    p.add_argument("--out", "-o", metavar="FILE", help="write to FILE (default stdout)")
    p.add_argument("--since", metavar="DATE", help="only measurements finished at or after DATE (ISO 8601, UTC)")
    p.add_argument("--until", metavar="DATE", help="only measurements finished before DATE")
    p.add_argument("--status", choices=("ok", "failed", "aborted"), help="only this status")
    p.add_argument("--part", metavar="SERIAL", help="only the measurements of this part ID")
    p.add_argument("--trace", metavar="ID", help="export the raw trace of one measurement (UUID or seq) as trace CSV "
                                                 "(t in s, angle in rad; `moi identify` reads it)")


def run(args: argparse.Namespace) -> int:
    with open_store(args) as store:
        if args.trace:
            m = store.get(args.trace, trace=True)
            if m is None:
                raise InputFileError(f"no single measurement matches {args.trace!r}")
            if m.trace_t is None:
                raise InputFileError(f"measurement {m.uuid} has no stored trace ({m.status}; or store_trace = false)")
            text = trace_text(m)
        else:
            if args.format == "dfq":
                data = _dfq(store, args)
                if args.out:
                    write_atomic(args.out, data, "DFQ file")
                else:
                    sys.stdout.buffer.write(data)
                return 0
            rows = list(reversed(store.list(
                limit=None, full=True, status=args.status, part_id=args.part, recipe=args.recipe,
                since=parse_time(args.since) if args.since else None,
                until=parse_time(args.until) if args.until else None)))  # oldest first
            text = json_text(rows) if args.format == "json" else csv_text(rows)
    if args.out:
        write_text_atomic(args.out, text)
    else:
        sys.stdout.write(text)
    return 0


def _dfq(store, args: argparse.Namespace) -> bytes:
    return dfq_bytes(store, args.recipe, unit=args.unit, part_id=args.part,
                     since=parse_time(args.since) if args.since else None,
                     until=parse_time(args.until) if args.until else None)
