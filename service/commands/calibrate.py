"""`moi calibrate CAL.toml --rig RIG.toml --out RIG_OUT.toml`: k and tare inertia of a torsion rig.

CAL.toml lists the references, each with a known added inertia and either a
trace (identified here) or the damped main frequency ω_m and amplitude
modulation ζ as a monocular-vision torsion pendulum reports them:

    [[reference]]
    name = "empty"
    trace = "empty.csv"            # path relative to CAL.toml
    added_inertia = 0.0            # kg·m²

    [[reference]]
    name = "two cylinders, L = 50 mm"
    omega = 6.9930                 # ω_m, rad/s (damped main frequency)
    zeta = -0.06017                # amplitude modulation ζ, 1/s (either sign)
    cylinders = [{ mass = 0.5021, diameter = 0.06007, distance = 0.05 },
                 { mass = 0.5006, diameter = 0.06004, distance = 0.05 }]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from measurement.calibration import Cylinder, Reference, calibrate_torsion
from measurement.errors import CalibrationError

from ..files import read_rig, read_toml, read_trace, write_rig

HELP = "calibrate a torsion rig's stiffness and tare inertia from reference loads"

_REF_KEYS = {"name", "trace", "added_inertia", "cylinders", "omega", "zeta", "omega_n"}
_CYL_KEYS = {"mass", "diameter", "distance", "own_inertia"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("calibration", metavar="CAL.toml", help="reference loads (see `moi calibrate --help`)")
    p.add_argument("--rig", required=True, metavar="RIG.toml", help="the torsion rig (its stiffness may be absent)")
    p.add_argument("--out", metavar="RIG_OUT.toml", help="write the rig with the calibrated stiffness and tare_inertia")
    p.add_argument("--json", action="store_true", help="print the calibration as JSON")


def _number(ref_name: str, key: str, value, allow_zero: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CalibrationError(f"reference {ref_name!r}: {key} must be a number, got {value!r}")
    return float(value)


def load_references(path: str, rig) -> list[Reference]:
    from measurement import Options, identify  # scipy: only when a reference is a trace

    doc = read_toml(path, "calibration file")
    refs = doc.get("reference")
    if set(doc) - {"reference"} or not isinstance(refs, list) or not refs:
        raise CalibrationError(f"{path}: expected [[reference]] tables only (name, trace or omega/zeta, added_inertia or cylinders)")
    base = Path(path).parent
    out = []
    for i, r in enumerate(refs, start=1):
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
    cal = calibrate_torsion(load_references(args.calibration, rig))
    if args.out:
        new = replace(rig, stiffness=cal.stiffness, stiffness_std=cal.stiffness_std,
                      tare_inertia=cal.tare_inertia, tare_inertia_std=cal.tare_inertia_std)
        write_rig(new, args.out, comment=f"calibrated by moi calibrate from {args.calibration}")
    if args.json:
        print(json.dumps(cal.to_dict()))
    else:
        print(cal.report())
        if args.out:
            print(f"rig written to {args.out}")
    return 0
