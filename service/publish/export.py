"""The export files of stored measurements: CSV (one row each), JSON (full payloads), AQDEF/Q-DAS DFQ (a
recipe's parts, for SPC systems) and one raw trace. `moi export` writes them, the web page serves them.

Values are SI (kg·m², rad/s, rad; the CSV's ``unit`` column and the JSON's ``unit`` key say the unit of
inertia); every time is ISO 8601 with its offset (UTC), e.g. 2025-01-31T12:00:00.123+00:00."""

from __future__ import annotations

import csv
import io
import json

from measurement import Trace
from measurement.units import SI, inertia_unit
from service.errors import InputFileError
from service.publish.dfq import ENCODING, dfq_text
from service.publish.payload import fmt_time, iso_utc

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


def dfq_bytes(store, recipe_name: str | None, *, unit: str | None = None, part_id: str | None = None,
              since: float | None = None, until: float | None = None) -> bytes:
    """The DFQ file of one recipe's completed parts (oldest first); ``recipe_name`` None: the store's only one."""
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


def json_text(rows) -> str:
    """Stored measurements (oldest first) as the JSON export: each one's summary, payload and rig."""
    # the times as in the CSV and the payload: ISO 8601 with the offset
    docs = [m.summary() | {k: iso_utc(getattr(m, k)) if getattr(m, k) is not None else None
                           for k in ("started_at", "finished_at", "published_at")}
            | {"unit": EXPORT_UNIT, "payload": m.payload, "rig": m.rig} for m in rows]
    return json.dumps(docs, indent=2, ensure_ascii=False) + "\n"


def csv_text(rows) -> str:
    """Stored measurements (oldest first) as the CSV export: one row each, the columns CSV_COLUMNS."""
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
        w.writerow(["" if rec.get(k) is None else (repr(rec[k]) if isinstance(rec[k], float) else csv_cell(rec[k]))
                    for k in CSV_COLUMNS])
    return buf.getvalue()


#: first characters that make a spreadsheet read a cell as a formula (OWASP, "CSV Injection")
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value: object) -> object:
    """A text cell a spreadsheet will show as text: one starting like a formula gets a leading apostrophe
    (a part ID ``=1+cmd|'/c calc'!A1`` written by a PLC must not run when the export is opened).
    Numbers are written as numbers."""
    if isinstance(value, str) and value.startswith(FORMULA_STARTS):
        return "'" + value
    return value
