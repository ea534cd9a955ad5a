"""`moi export`: write stored measurements as CSV (one row each), JSON (full payloads) or AQDEF/Q-DAS DFQ
(a recipe's parts, for SPC systems), or one raw trace.

Values are SI (kg·m², rad/s, rad; the CSV's ``unit`` column and the JSON's ``unit`` key say the unit of
inertia); every time is ISO 8601 with its offset (UTC), e.g. 2025-01-31T12:00:00.123+00:00."""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys

from measurement import Trace
from measurement.units import SI

from service.errors import InputFileError
from service.sources.files import write_atomic, write_text_atomic
from service.publish.payload import iso_utc
from ._common import add_store_arguments, fmt_time, open_store, parse_time


CSV_COLUMNS = (
    "seq", "uuid", "status", "trigger", "device_id", "software_version", "started_at", "finished_at",
    "published_at", "J", "J_std", "J_object", "J_object_std", "omega_n", "omega_n_std", "damping_ratio",
    "damping_ratio_std", "residual_rms_before", "residual_rms_after", "noise_floor", "effects",
    "added_effects", "flags", "error",
    "part_id", "part_uuid", "recipe", "recipe_version", "release_index", "releases", "verdict", "part_verdict",
    "part_value", "part_U", "calibration_date", "unit",
)

#: the unit of every inertia value in the CSV and JSON exports (stored values are SI)
EXPORT_UNIT = SI


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
            text = _json(rows) if args.format == "json" else _csv(rows)
    if args.out:
        write_text_atomic(args.out, text)
    else:
        sys.stdout.write(text)
    return 0


def _dfq(store, args: argparse.Namespace) -> bytes:
    return dfq_bytes(store, args.recipe, unit=args.unit, part_id=args.part,
                     since=parse_time(args.since) if args.since else None,
                     until=parse_time(args.until) if args.until else None)


def dfq_bytes(store, recipe_name: str | None, *, unit: str | None = None, part_id: str | None = None,
              since: float | None = None, until: float | None = None) -> bytes:
    """The DFQ file of one recipe's completed parts (oldest first); ``recipe_name`` None: the store's only one."""
    from measurement.units import inertia_unit

    from service.publish.dfq import ENCODING, dfq_text

    recipes = store.recipes()
    name = recipe_name
    if name is None:
        if len(recipes) != 1:
            raise InputFileError("a DFQ file holds one part type: give the recipe (recipes in the store: "
                                 f"{', '.join(recipes) or 'none'})")
        name = recipes[0]
    rows = list(reversed(store.list(limit=None, full=True, recipe=name, parts_only=True, part_id=part_id,
                                    since=since, until=until)))
    if not rows:
        raise InputFileError(f"no completed parts of recipe {name!r} in {store.path}")
    recipe = rows[-1].payload["recipe"]  # the limits of the newest part's recipe version
    unit = inertia_unit(unit or recipe.get("display_unit") or SI)
    return dfq_text(recipe, rows, unit).encode(ENCODING, errors="replace")


def trace_text(m) -> str:
    """The raw trace of a stored measurement (with its trace) as trace CSV, with where it came from."""
    return Trace(m.trace_t, m.trace_angle, source=m.uuid).to_csv(
        f"moi measurement {m.uuid} (seq {m.seq}), finished {fmt_time(m.finished_at)} UTC, device {m.device_id}")


def _json(rows) -> str:
    # the times as in the CSV and the payload: ISO 8601 with the offset
    docs = [m.summary() | {k: iso_utc(getattr(m, k)) if getattr(m, k) is not None else None
                           for k in ("started_at", "finished_at", "published_at")}
            | {"unit": EXPORT_UNIT, "payload": m.payload, "rig": m.rig} for m in rows]
    return json.dumps(docs, indent=2, ensure_ascii=False) + "\n"


def _csv(rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for m in rows:
        p = m.payload or {}
        s = m.summary()
        rec = {**{k: p.get(k) for k in CSV_COLUMNS}, **{k: v for k, v in s.items() if k in CSV_COLUMNS and v is not None}}
        rec["effects"] = " ".join(p.get("effects") or [])
        rec["added_effects"] = " ".join(p.get("added_effects") or [])
        rec["flags"] = " ".join(m.flags)
        rec["calibration_date"] = (p.get("calibration") or {}).get("date")
        rec["unit"] = EXPORT_UNIT
        for k in ("started_at", "finished_at", "published_at"):
            rec[k] = iso_utc(s[k]) if s[k] is not None else ""
        w.writerow(["" if rec.get(k) is None else (repr(rec[k]) if isinstance(rec[k], float) else csv_text(rec[k]))
                    for k in CSV_COLUMNS])
    return buf.getvalue()


#: first characters that make a spreadsheet read a cell as a formula (OWASP, "CSV Injection")
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def csv_text(value: object) -> object:
    """A text cell a spreadsheet will show as text: one starting like a formula gets a leading apostrophe
    (a part ID ``=1+cmd|'/c calc'!A1`` written by a PLC must not run when the export is opened).
    Numbers are written as numbers."""
    if isinstance(value, str) and value.startswith(FORMULA_STARTS):
        return "'" + value
    return value
