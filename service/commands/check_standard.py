"""`moi check-standard SOURCE --rig RIG.toml --reference J --reference-U U`: measure a check standard.

A check standard is a reference artifact of certified inertia J_ref ± U_ref
(its calibration certificate, expanded, k = 2) measured on the rig as if it
were a part. The normalised error

    E_n = |J − J_ref| / √(U² + U_ref²)

(ISO/IEC 17043, B.4.1.1) must be ≤ 1: the result's budget then covers what
the rig actually does. Measured regularly, the history shows drift before it
shows as wrong parts: ``--history`` lists it with an individuals control
chart of the deviations J − J_ref (its limits and run rules as in `moi spc`).

With a result store (``--state-dir`` or ``--config``) every check is kept;
the appliance then marks its results ``calibration_due`` while the newest
check has failed (until the rig is calibrated again, or a check passes).
Exit status 0 when the check passes, 3 when it fails (2: bad input).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time

from measurement.verdict import QUANTITIES
from service.commands._common import add_store_arguments, find_store_dir
from service.errors import InputFileError
from service.names import name_problem, shown

#: exit status of a check that failed (E_n > 1): not bad input (2), not a bug (1)
EXIT_FAILED = 3


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = __doc__.split("\n\n", 1)[1]
    p.add_argument("source", metavar="SOURCE", nargs="?", help="the check standard's swing: trace CSV, marker "
                   "track CSV, video or image folder (not with --history)")
    p.add_argument("--rig", metavar="RIG.toml", help="the rig file it was measured on")
    p.add_argument("--reference", type=float, metavar="J_REF", help="the certified inertia of the artifact, kg·m²")
    p.add_argument("--reference-U", type=float, metavar="U_REF",
                   help="its expanded uncertainty (certificate, k = 2), kg·m²")
    p.add_argument("--quantity", default="J_object", choices=QUANTITIES,
                   help="what the certificate states (default J_object: the artifact without the fixture)")
    p.add_argument("--name", default="check standard", help="the artifact's name (its history is kept by name)")
    p.add_argument("--history", action="store_true", help="list the stored checks and their control chart")
    p.add_argument("--plot", metavar="FILE.png", help="with --history: write the control chart of the deviations")
    p.add_argument("--json", action="store_true", help="print JSON")
    add_store_arguments(p)


def run(args: argparse.Namespace) -> int:
    if (problem := name_problem("check_standard", args.name)) is not None:
        raise InputFileError(f"--name: {problem}")
    if args.history:
        return _history(args)
    if args.source is None or args.rig is None or args.reference is None or args.reference_U is None:
        raise InputFileError("moi check-standard: give SOURCE, --rig, --reference (kg·m²) and --reference-U "
                             "(kg·m²), or --history")
    from measurement import Options, identify  # scipy: only when identifying
    from measurement.uncertainty import check_standard
    from service.sources.dispatch import load_source
    from service.sources.files import read_rig

    rig = read_rig(args.rig)
    result = identify(load_source(args.source, rig=rig), rig, Options())
    budget = result.uncertainty_budget.get(args.quantity)
    if budget is None:
        raise InputFileError(f"{args.rig}: the rig gives no {args.quantity} (stiffness or m·S, a tare for J_object, "
                             "[object] for J_object_axis); expected a rig that does")
    check = check_standard(args.name, args.quantity, budget.value, budget.U, args.reference, args.reference_U)
    record = check.to_dict() | {"source": str(args.source), "rig": args.rig, "flags": list(result.flags),
                                "coverage_factor": budget.coverage_factor}
    stored = None
    if args.state_dir or args.config:
        from service.persistence.store import Store

        with Store(find_store_dir(args) if args.config else args.state_dir) as store:
            store.record_check_standard(record, finished_at=time.time())
        stored = True
    if args.json:
        print(json.dumps(record | {"stored": bool(stored)}, ensure_ascii=False, allow_nan=False))
    else:
        verdict = "PASS" if check.passed else "FAIL: the budget does not cover the deviation, or the rig has drifted"
        print(f"check standard {check.name!r}: {check.quantity} = {check.value:.7g} ± {check.U:.2g} kg·m² (U), "
              f"certificate {check.reference:.7g} ± {check.reference_U:.2g} kg·m²")
        print(f"    deviation {check.value - check.reference:+.3g} kg·m², E_n = {check.E_n:.2f} → {verdict}")
        print("    stored in the result store" if stored else "    not stored (give --state-dir or --config to keep it)")
    sys.stdout.flush()
    return 0 if check.passed else EXIT_FAILED


def _history(args: argparse.Namespace) -> int:
    from measurement.spc import SpcError, individuals
    from service.commands._common import open_store
    from service.sources.files import check_output_path

    if args.plot:  # a bad path is refused before the work
        if not args.plot.lower().endswith(".png"):
            raise InputFileError(f"--plot {args.plot!r}: the chart is a PNG; give a file name ending in .png")
        check_output_path(args.plot, "chart file")
    with open_store(args) as store:
        rows = list(reversed(store.check_standards(limit=None)))
    if args.name != "check standard":
        rows = [r for r in rows if r["name"] == args.name]
    chart = None
    with contextlib.suppress(SpcError):  # fewer than 2 checks: no chart yet
        chart = individuals([r["deviation"] for r in rows])
    if args.plot and chart is not None:
        from service.publish.plot import plot_control_chart

        plot_control_chart(chart, args.plot, title=f"check standard {args.name}: J − J_ref")
    if args.json:
        print(json.dumps({"checks": rows, "chart": None if chart is None else chart.to_dict()}, ensure_ascii=False))
        return 0
    if not rows:
        print("no check standard measured yet")
        return 0
    print(f"{'when (UTC)':<20} {'name':<20} {'deviation':>11} {'E_n':>6}  result")
    for r in rows:
        when = time.strftime("%Y-%m-%d %H:%M", time.gmtime(r["finished_at"]))
        print(f"{when:<20} {shown('check_standard', r['name'])[:20]:<20} {r['deviation']:>+11.3g} {r['E_n']:>6.2f}  "
              f"{'pass' if r['passed'] else 'FAIL'}")
    if chart is not None:
        print("the deviation J − J_ref, check by check:")
        print(chart.report())
        if args.plot:
            print(f"chart written to {args.plot}")
    return 0

