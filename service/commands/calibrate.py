"""`moi calibrate CAL.toml --rig RIG.toml --out RIG_OUT.toml`: k and tare inertia of a torsion rig.

CAL.toml lists the references, each with a known added inertia and either a
trace (identified here) or the damped main frequency ω_m and amplitude
modulation ζ as a monocular-vision torsion pendulum reports them:

    [[reference]]
    name = "empty"
    trace = "empty.csv"            # path relative to CAL.toml
    added_inertia = 0.0            # kg·m²
    added_inertia_std = 0.0        # 1σ of the known inertia, kg·m² (its certificate)
    certificate = "none: nothing added"   # the certificate's identifier (optional, kept with the calibration)

    [[reference]]
    name = "two cylinders, L = 50 mm"
    omega = 6.9930                 # ω_m, rad/s (damped main frequency)
    zeta = -0.06017                # amplitude modulation ζ, 1/s (either sign)
    omega_n_std = 2e-4             # 1σ of the frequency, rad/s (a trace's comes from its fit)
    cylinders = [{ mass = 0.5021, diameter = 0.06007, distance = 0.05,
                   mass_std = 1e-4, diameter_std = 1e-5, distance_std = 2e-5 },
                 { mass = 0.5006, diameter = 0.06004, distance = 0.05 }]

A reference released more than once (remounted, swung again) repeats its
table with the same name and known inertia and its new trace (or ω): each
release is a point of the fit, and the releases of the references given
more than once are pooled into the rig's reproducibility between releases
(ISO 5725-2: the relative within-reference standard deviation of ω_n, ν =
Σ(n_i − 1)), written with the calibration as ``reproducibility`` and
``reproducibility_dof`` once ν ≥ 2 (each of two references released twice,
or one three times). One release's u then counts it in place of the
documented default (docs/uncertainty.md).

The regression uses every stated uncertainty (weighted, errors in the known
inertia as well as in ω_n: measurement/calibration.py); a reference whose σ
is not stated is said to be so. With few references a small misfit does not
shrink k's σ below what the certificates allow.

With ``--out`` the rig file gets the calibrated k and I0 with their 1σ and a
``[calibration]`` table: the date (``--date``, default today, UTC), the
validity period (``--valid-days``, default 365), the calibration file and
every reference used with its known inertia, its uncertainty, its
certificate, the measured ω_n ± 1σ and the fit's misfit, and the covariance
of k and I0 (``stiffness_tare_covariance``). Results measured after date +
valid_days carry the flag ``calibration_due`` and the appliance refuses to
measure parts; k, I0 and their covariance enter every J's uncertainty budget
(docs/uncertainty.md). Each calibration written is also appended to the
rig's history beside RIG_OUT.toml, RIG_OUT.calibrations.jsonl (who ran it:
``--by``, else the login name), which the web page's Calibration lists;
calibrate in place (``--out`` the file ``--rig`` names) to keep one history
per rig. The daemon reads the rig file when it starts: restart it after.
"""

from __future__ import annotations

import argparse
import datetime as dt
import getpass
import json
import math
import socket
from dataclasses import replace
from pathlib import Path

from measurement.calibration import Cylinder, Reference, calibrate_torsion, cylinder_inertia_std, reproducibility
from measurement.errors import CalibrationError
from measurement.reproducibility import MIN_DOF, Reproducibility
from measurement.rig import CalibrationRecord
from service.errors import InputFileError
from service.names import name_problem
from service.sources import calibrations
from service.sources.files import read_rig, read_toml, read_trace, write_rig

_REF_KEYS = {"name", "trace", "added_inertia", "added_inertia_std", "cylinders", "omega", "zeta", "omega_n",
             "omega_n_std", "certificate"}
_CYL_VALUE_KEYS = {"mass", "diameter", "distance", "own_inertia"}
_CYL_STD_KEYS = {"mass_std", "diameter_std", "distance_std"}
_CYL_KEYS = _CYL_VALUE_KEYS | _CYL_STD_KEYS


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
    p.add_argument("--by", metavar="NAME",
                   help="who calibrated, for the rig's calibration history (default: the login name)")


def _number(ref_name: str, key: str, value, allow_zero: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CalibrationError(f"reference {ref_name!r}: {key} must be a finite number, got {value!r}")
    return float(value)


def _std(ref_name: str, key: str, value, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
        raise CalibrationError(f"reference {ref_name!r}: {key} must be a standard uncertainty >= 0 {unit}, got {value!r}")
    return float(value)


def _known_inertia(name: str, r: dict) -> tuple[float, float | None]:
    """A reference's known added inertia and its 1σ (kg·m²; None: not stated), from added_inertia or cylinders."""
    if ("added_inertia" in r) == ("cylinders" in r):
        raise CalibrationError(f"reference {name!r}: give exactly one of added_inertia (kg·m²) or cylinders")
    if "cylinders" in r:
        cyls = r["cylinders"]
        if not isinstance(cyls, list) or not all(isinstance(c, dict) and set(c) <= _CYL_KEYS and {"mass", "diameter", "distance"} <= set(c) for c in cyls):
            raise CalibrationError(f"reference {name!r}: cylinders must be tables with mass (kg), diameter (m), distance (m)")
        added, var = 0.0, 0.0
        for c in cyls:
            cyl = Cylinder(**{k: v for k, v in c.items() if k in _CYL_VALUE_KEYS})
            added += cyl.inertia
            stds = {k: _std(name, f"cylinder {k}", v, "(kg or m)") for k, v in c.items() if k in _CYL_STD_KEYS}
            var += cylinder_inertia_std(cyl, **stds) ** 2
        # a cylinder's tolerances given: its part of the reference's σ (the rest from added_inertia_std)
        tol = math.sqrt(var) if any(set(c) & _CYL_STD_KEYS for c in cyls) else None
    else:
        added = _number(name, "added_inertia", r["added_inertia"])
        tol = None
    u_added = None
    if "added_inertia_std" in r:
        u_added = _std(name, "added_inertia_std", r["added_inertia_std"], "kg·m²")
    if tol is not None:
        u_added = math.hypot(u_added or 0.0, tol)
    return added, u_added


def load_references(path: str, rig) -> list[Reference]:
    """The references of CAL.toml, each with its stated uncertainties (None where not stated)."""
    return read_references(path, rig)[0]


def read_references(path: str, rig) -> tuple[list[Reference], float | None]:
    """(the references of CAL.toml, the swing amplitude their traces' ω_n are read at, rad; None: no trace).

    Where a spring's stiffness changes with the amplitude, k is the stiffness at the amplitude its
    references were read at: each trace is read at one amplitude, the mean of the traces' own
    (``measurement.identification.measurand``), which the rig's ``[calibration] amplitude`` keeps so that a
    part's ω is read there too."""
    from measurement import Options, identify  # scipy: only when a reference is a trace

    doc = read_toml(path, "calibration file")
    refs = doc.get("reference")
    if set(doc) - {"reference"} or not isinstance(refs, list) or not refs:
        raise CalibrationError(f"{path}: expected [[reference]] tables only (name, trace or omega/zeta, added_inertia or cylinders)")
    base = Path(path).parent
    out = []
    # the references are read with no earlier calibration's amplitude, each at its own first
    free = replace(rig, stiffness=None, stiffness_std=None, stiffness_tare_covariance=None, calibration=None)
    traced: list[tuple[int, tuple, float]] = []  # (index in out, (trace, stated σ, a law fitted), its amplitude)
    for i, r in enumerate(refs, start=1):
        if not isinstance(r, dict):
            raise CalibrationError(f"{path}: reference {i} is {r!r}; expected a [[reference]] table")
        name = r.get("name", f"reference {i}")
        if (problem := name_problem("reference", name)) is not None:
            raise CalibrationError(f"{path}: reference {i}: {problem}")
        unknown = set(r) - _REF_KEYS
        if unknown:
            raise CalibrationError(f"reference {name!r}: unknown key(s) {sorted(unknown)}; expected {sorted(_REF_KEYS)}")
        added, u_added = _known_inertia(name, r)
        u_omega = _std(name, "omega_n_std", r["omega_n_std"], "rad/s") if "omega_n_std" in r else None
        if "trace" in r:
            trace = read_trace(base / str(r["trace"]))
            result = identify(trace, free, Options())
            # the record's own uncertainty of ω_n: the fit and its model form, unless the file states one
            out.append(Reference(name, added, result.omega_n,
                                 u_omega if u_omega is not None else (result.omega_n_u or result.omega_n_std), u_added))
            if result.omega_n_read_at.basis != "small-swing limit":
                traced.append((len(out) - 1, (trace, u_omega, bool(result.stiffness)), result.omega_n_read_at.amplitude))
        elif "omega" in r and "zeta" in r:
            ref = Reference.from_damped(name, added, _number(name, "omega", r["omega"]), _number(name, "zeta", r["zeta"]),
                                        u_added)
            out.append(replace(ref, omega_n_std=u_omega))
        elif "omega_n" in r:
            out.append(Reference(name, added, _number(name, "omega_n", r["omega_n"]), u_omega, u_added))
        else:
            raise CalibrationError(f"reference {name!r}: needs a trace, or omega and zeta, or omega_n")
        if "certificate" in r:
            certificate = r["certificate"].strip() if isinstance(r["certificate"], str) else r["certificate"]
            if (problem := name_problem("certificate", certificate)) is not None:
                raise CalibrationError(f"reference {name!r}: {problem}; expected the certificate's identifier")
            out[-1] = replace(out[-1], certificate=certificate)
    if not traced:
        return out, None
    amplitude = sum(a for _, _, a in traced) / len(traced)
    for k, (trace, u_omega, law), own in traced:
        if law and own != amplitude:
            # one amplitude for every reference: a fitted amplitude law reads its ω there (the others' ω is the
            # same at every amplitude their model knows)
            result = identify(trace, free, Options(reference_amplitude=amplitude))
            out[k] = replace(out[k], omega_n=result.omega_n,
                             omega_n_std=u_omega if u_omega is not None else (result.omega_n_u or result.omega_n_std))
    return out, amplitude


def run(args: argparse.Namespace) -> int:
    rig = read_rig(args.rig)
    if rig.kind != "torsion":
        raise CalibrationError(f"{args.rig}: calibration fits k and I0 of a torsion rig; this rig is {rig.kind}")
    if args.valid_days <= 0:
        raise CalibrationError(f"--valid-days must be > 0, got {args.valid_days}")
    by = _who(args.by)
    try:
        date = dt.date.fromisoformat(args.date) if args.date else dt.datetime.now(dt.UTC).date()
    except ValueError:
        raise CalibrationError(f"--date must be a date like 2026-01-31, got {args.date!r}") from None
    refs, amplitude = read_references(args.calibration, rig)
    cal = calibrate_torsion(refs)
    repro = reproducibility(refs)
    kept = repro if repro is not None and repro.dof >= MIN_DOF else None  # a thinner figure would set k near 13
    references = [{k: v for k, v in ref.items() if v is not None} for ref in cal.to_dict()["references"]]
    record = CalibrationRecord(date, args.valid_days, tuple(references), str(args.calibration), amplitude,
                               None if kept is None else kept.relative, None if kept is None else int(kept.dof))
    until = record.valid_until
    assert until is not None  # valid_days was given
    if args.out:
        new = replace(rig, stiffness=cal.stiffness, stiffness_std=cal.stiffness_std,
                      tare_inertia=cal.tare_inertia, tare_inertia_std=cal.tare_inertia_std,
                      stiffness_tare_covariance=cal.covariance, calibration=record)
        write_rig(new, args.out, comment=f"calibrated by moi calibrate from {args.calibration}", keep_from=args.rig)
        try:
            history = calibrations.append(args.out, _history_entry(args, by, cal, record, references))
        except InputFileError as exc:
            raise InputFileError(f"rig written to {args.out}, but its calibration is not in the history: {exc}") from None
    if args.json:
        print(json.dumps(cal.to_dict() | {"date": date.isoformat(), "valid_days": args.valid_days,
                                          "valid_until": until.isoformat()}))
    else:
        print(cal.report())
        print(f"    calibrated on {date.isoformat()}, valid until {until.isoformat()}")
        print(_reproducibility_line(repro))
        if args.out:
            print(f"rig written to {args.out}; calibration appended to {history}")
    return 0


def _reproducibility_line(r: Reproducibility | None) -> str:
    """What the calibration says of the rig's scatter between releases (kept in the rig file from ν ≥ MIN_DOF)."""
    if r is None or r.relative is None:
        return ("    reproducibility between releases: not measured (each reference released once): one release's u "
                "counts the documented default; release each reference twice to measure it")
    figure = f"±{100 * r.relative:.2g} % of ω_n ({r.note()}, ν = {r.dof:.0f})"
    if r.dof < MIN_DOF:
        return (f"    reproducibility between releases: {figure}, fewer than {MIN_DOF} degrees of freedom: not kept; "
                "release two references twice")
    return f"    reproducibility between releases: {figure}: kept with the calibration, in one release's u"


def _who(by: str | None) -> str:
    """Who calibrates: ``--by``, else the login name (checked as every name is: it reaches the terminal, the
    history and the page)."""
    if by is not None:
        if (problem := name_problem("person", by)) is not None:
            raise CalibrationError(f"--by: {problem}")
        return by
    try:
        login = getpass.getuser()
    except (OSError, KeyError):
        return "unknown"
    if (problem := name_problem("person", login)) is not None:
        raise CalibrationError(f"the login name is not a good name ({problem}); give --by NAME")
    return login


def _history_entry(args: argparse.Namespace, by: str, cal, record: CalibrationRecord,
                   references: list[dict]) -> dict:
    """One line of the rig's calibration history (``service.sources.calibrations``)."""
    from service import __version__

    return {"date": record.date.isoformat(), "valid_days": record.valid_days,
            "valid_until": record.valid_until.isoformat() if record.valid_until else None,
            "recorded_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
            "by": by, "host": socket.gethostname(), "software": f"moi {__version__}",
            "stiffness": cal.stiffness, "stiffness_std": cal.stiffness_std, "tare_inertia": cal.tare_inertia,
            "tare_inertia_std": cal.tare_inertia_std, "stiffness_tare_covariance": cal.covariance,
            "references": references, "calibration_file": str(Path(args.calibration).resolve()),
            "rig_file": str(Path(args.out).resolve()), "from_rig": str(Path(args.rig).resolve())}
