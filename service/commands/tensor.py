"""`moi tensor PLAN.toml [--json] [--plot FILE.png]`: the inertia tensor of a part from a multi-orientation set.

The plan file names the rig every orientation swings on, the part (mass for the
parallel-axis step, the products-of-inertia convention) and one
``[[orientation]]`` per mounting: the swing axis in the part's frame, its
releases (trace or marker track CSVs) and, optionally, where the centre of mass
sits off the axis. Paths are relative to the plan file. Everything that can be
checked is checked before the first trace is identified.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from service.errors import InputFileError
from service.sources.files import check_output_path, read_rig, read_toml, write_atomic

#: what a plan file holds beside the plan itself (``measurement.tensor.TensorPlan.from_dict``)
PLAN_FILE_KEYS = ("rig",)
ORIENTATION_FILE_KEYS = ("traces",)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("plan", metavar="PLAN.toml",
                   help="tensor plan: rig = \"rig.toml\", [part] (name, mass, mass_std, poi_convention) and one "
                        "[[orientation]] per mounting (axis, traces, optional offset, offset_std, name)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the report")
    p.add_argument("--plot", metavar="FILE.png",
                   help="write each orientation's inertia against the tensor's, and the normalised residuals, to a PNG")


def read_plan_file(path: str | Path) -> tuple[Any, Any, list[list[Path]]]:
    """The plan, the rig and each orientation's trace paths, all checked (nothing identified yet)."""
    from measurement.tensor import TensorPlan
    from measurement.tensor_inputs import RigShared

    path = Path(path)
    doc = read_toml(path, "tensor plan")
    base = path.parent
    rig_name = doc.get("rig")
    if not isinstance(rig_name, str) or not rig_name:
        raise InputFileError(f"tensor plan {str(path)!r}: rig = \"rig.toml\" is missing; every orientation swings "
                             "on that rig (its tare included)")
    plan = TensorPlan.from_dict(doc, extra_orientation_keys=ORIENTATION_FILE_KEYS, extra_keys=PLAN_FILE_KEYS)
    rig = read_rig(base / rig_name)
    RigShared.of(rig)
    traces: list[list[Path]] = []
    missing: list[str] = []
    for o, row in zip(plan.orientations, doc["orientation"]):
        names = row.get("traces")
        if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names):
            raise InputFileError(f"tensor plan: orientation {o.name!r} needs traces = [\"file.csv\", ...] "
                                 "(one or more releases)")
        paths = [base / n for n in names]
        missing += [str(p) for p in paths if not p.is_file()]
        traces.append(paths)
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise InputFileError(f"tensor plan: trace(s) not found: {', '.join(missing[:3])}{more}")
    return plan, rig, traces


def run(args: argparse.Namespace) -> int:
    if args.plot:  # a bad plot path is refused before the work, not after it
        if not args.plot.lower().endswith(".png"):
            raise InputFileError(f"--plot {args.plot!r}: the plot is a PNG; give a file name ending in .png")
        check_output_path(args.plot, "plot file")
    plan, rig, traces = read_plan_file(args.plan)

    from measurement import identify
    from measurement.reports import tensor_report
    from measurement.tensor import solve_results
    from service.sources.dispatch import load_source

    results = [[identify(load_source(p, rig=rig), rig) for p in paths] for paths in traces]
    tensor = solve_results(plan, results, rig)
    if args.json:
        d = tensor.to_dict()
        for row, paths in zip(d["orientations"], traces):
            row["traces"] = [str(p) for p in paths]
        import json
        sys.stdout.write(json.dumps(d, ensure_ascii=False, allow_nan=False) + "\n")
    else:
        print(tensor_report(tensor))
    sys.stdout.flush()
    if args.plot:
        from service.publish.plot import render_tensor_png
        write_atomic(args.plot, render_tensor_png(tensor), "plot file")
        if not args.json:
            print(f"plot written to {args.plot}")
    return 0
