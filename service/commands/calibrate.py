"""`moi calibrate CAL.toml --rig RIG.toml --out RIG_OUT.toml`: k and tare inertia of a torsion rig.

CAL.toml lists the references, each with a known added inertia and either a
trace (identified here) or the damped main frequency ω_m and amplitude
modulation ζ as a monocular-vision torsion pendulum reports them:

    [[reference]]
    name = "empty"
    trace = "empty.csv"            # path relative to CAL.toml
    added_inertia = 0.0            # kg·m²
    added_inertia_std = 0.0        # optional: 1σ of the known inertia, kg·m² (recorded)

    [[reference]]
    name = "two cylinders, L = 50 mm"
    omega = 6.9930                 # ω_m, rad/s (damped main frequency)
    zeta = -0.06017                # amplitude modulation ζ, 1/s (either sign)
    cylinders = [{ mass = 0.5021, diameter = 0.06007, distance = 0.05 },
                 { mass = 0.5006, diameter = 0.06004, distance = 0.05 }]

With ``--out`` the rig file gets the calibrated k and I0 with their 1σ and a
``[calibration]`` table: the date (``--date``, default today, UTC), the
validity period (``--valid-days``, default 365), the calibration file and
every reference used with its known inertia, its uncertainty, the measured
ω_n ± 1σ and the fit's misfit. Results measured after date + valid_days
carry the flag ``calibration_due``; the 1σ of k enters every J's expanded
uncertainty (``J_std_calibration``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
from dataclasses import replace
from pathlib import Path

from measurement.calibration import Cylinder, Reference, calibrate_torsion
from measurement.errors import CalibrationError
from measurement.rig import CalibrationRecord

from service.sources.files import read_rig, read_toml, read_trace, write_rig


_REF_KEYS = {"name", "trace", "added_inertia", "added_inertia_std", "cylinders", "omega", "zeta", "omega_n"}
_CYL_KEYS = {"mass", "diameter", "distance", "own_inertia"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = ("the calibration file (an example: examples/calibration.toml):\n"
                + __doc__.split("\n\n", 1)[1])
    p.add_argument("calibration", metavar="CAL.toml", help="reference loads (file format below)")
    p.add_argument("--rig", required=True, metavar="RIG.toml", help="the torsion rig (its stiffness may be absent)")
    p.add_argument("--out", metavar="RIG_OUT.toml", help="write the rig with the calibrated stiffness and tare_inertia")
    p.add_argument("--json", action="store_true", help="print the calibration as JSON")
    p.add_argument("--date", metavar="YYYY-MM-DD", help="date of the calibration (default: today, UTC)")
    p.add_argument("--valid-days", type=int, default=365, metavar="DAYS",
                   help="validity period of the calibration, days (default 365); later results carry calibration_due")


def _number(ref_name: str, key: str, value, allow_zero: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CalibrationError(f"reference {ref_name!r}: {key} must be a finite number, got {value!r}")
    return float(value)


def load_references(path: str, rig, stds: dict[str, float] | None = None) -> list[Reference]:
    """The references of CAL.toml; ``stds`` (if given) receives name → added_inertia_std (kg·m²)."""
    from measurement import Options, identify  # scipy: only when a reference is a trace

    doc = read_toml(path, "calibration file")
    refs = doc.get("reference")
    if set(doc) - {"reference"} or not isinstance(refs, list) or not refs:
        raise CalibrationError(f"{path}: expected [[reference]] tables only (name, trace or omega/zeta, added_inertia or cylinders)")
    base = Path(path).parent
    out = []
    for i, r in enumerate(refs, start=1):
        if not isinstance(r, dict):
            raise CalibrationError(f"{path}: reference {i} is {r!r}; expected a [[reference]] table")
        name = str(r.get("name", f"reference {i}"))
        unknown = set(r) - _REF_KEYS
        if unknown:
            raise CalibrationError(f"reference {name!r}: unknown key(s) {sorted(unknown)}; expected {sorted(_REF_KEYS)}")
        if ("added_inertia" in r) == ("cylinders" in r):
            raise CalibrationError(f"reference {name!r}: give exactly one of added_inertia (kg·m²) or cylinders")
        if "cylinders" in r:
            cyls = r["cylinders"]
            if not isinstance(cyls, list) or not all(isinstance(c, dict) and set(c) <= _CYL_KEYS and {"mass", "diameter", "distance"} <= set(c) for c in cyls):
                raise CalibrationError(f"reference {name!r}: cylinders must be tables with mass (kg), diameter (m), distance (m)")
            added = sum(Cylinder(**c).inertia for c in cyls)
        else:
            added = _number(name, "added_inertia", r["added_inertia"])
        if "added_inertia_std" in r:
            u = _number(name, "added_inertia_std", r["added_inertia_std"])
            if u < 0:
                raise CalibrationError(f"reference {name!r}: added_inertia_std must be >= 0 kg·m², got {u!r}")
            if stds is not None:
                stds[name] = u
        if "trace" in r:
            trace = read_trace(base / str(r["trace"]))
            result = identify(trace, replace(rig, stiffness=None, stiffness_std=None), Options())
            out.append(Reference(name, added, result.omega_n, result.omega_n_std))
        elif "omega" in r and "zeta" in r:
            out.append(Reference.from_damped(name, added, _number(name, "omega", r["omega"]), _number(name, "zeta", r["zeta"])))
        elif "omega_n" in r:
            out.append(Reference(name, added, _number(name, "omega_n", r["omega_n"])))
        else:
            raise CalibrationError(f"reference {name!r}: needs a trace, or omega and zeta, or omega_n")
    return out


def run(args: argparse.Namespace) -> int:
    rig = read_rig(args.rig)
    if rig.kind != "torsion":
        raise CalibrationError(f"{args.rig}: calibration fits k and I0 of a torsion rig; this rig is {rig.kind}")
    if args.valid_days <= 0:
        raise CalibrationError(f"--valid-days must be > 0, got {args.valid_days}")
    try:
        date = dt.date.fromisoformat(args.date) if args.date else dt.datetime.now(dt.UTC).date()
    except ValueError:
        raise CalibrationError(f"--date must be a date like 2026-01-31, got {args.date!r}") from None
    stds: dict[str, float] = {}
    cal = calibrate_torsion(load_references(args.calibration, rig, stds))
    references = []
    for ref in cal.to_dict()["references"]:
        entry = {k: v for k, v in ref.items() if v is not None}
        if ref["name"] in stds:
            entry["added_inertia_std"] = stds[ref["name"]]
        references.append(entry)
    record = CalibrationRecord(date, args.valid_days, tuple(references), str(args.calibration))
    if args.out:
        new = replace(rig, stiffness=cal.stiffness, stiffness_std=cal.stiffness_std,
                      tare_inertia=cal.tare_inertia, tare_inertia_std=cal.tare_inertia_std, calibration=record)
        write_rig(new, args.out, comment=f"calibrated by moi calibrate from {args.calibration}", keep_from=args.rig)
    if args.json:
        print(json.dumps(cal.to_dict() | {"date": date.isoformat(), "valid_days": args.valid_days,
                                          "valid_until": record.valid_until.isoformat()}))
    else:
        print(cal.report())
        print(f"    calibrated on {date.isoformat()}, valid until {record.valid_until.isoformat()}")
        if args.out:
            print(f"rig written to {args.out}")
    return 0
