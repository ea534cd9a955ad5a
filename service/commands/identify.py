"""`moi identify SOURCE --rig RIG.toml [--camera CAM.toml] [--json] [--plot FILE.png|.svg|.pdf]`."""

from __future__ import annotations

import argparse
import sys

from measurement.effects import EFFECTS
from service.errors import InputFileError
from service.sources.files import check_output_path, read_rig, write_atomic


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="SOURCE", nargs="+", help="one or more releases of one object (several are "
                   "identified jointly: shared physics, per-release offset and sensor terms, and a test that they "
                   "agree); each a trace CSV (t in s, angle in rad), marker track CSV (t in s, two markers' image positions "
                        "ax, ay, bx, by in px: the camera's oblique view is measured from their distance and removed), "
                        "video file or image folder")
    p.add_argument("--rig", required=True, metavar="RIG.toml", help="rig file (kind, stiffness or mass/com_distance, declared effects)")
    p.add_argument("--camera", metavar="CAM.toml", help="camera file, for a video SOURCE")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the report")
    p.add_argument("--plot", metavar="FILE.png", help="write the trace, the fits and both residuals to a picture: "
                   "PNG, SVG or PDF by the file name's extension")
    p.add_argument("--no-discover", action="store_true", help="fit the declared model only (no discovery loop)")
    p.add_argument("--candidates", metavar="NAMES",
                   help=f"comma-separated effects the loop may add (default: all of {', '.join(EFFECTS)})")


def run(args: argparse.Namespace) -> int:
    from service.publish.plot import PLOT_FORMATS

    fmt = args.plot.rsplit(".", 1)[-1].lower() if args.plot and "." in args.plot else ""
    if args.plot:  # a bad plot path is refused before the work, not after it
        if fmt not in PLOT_FORMATS:
            raise InputFileError(f"--plot {args.plot!r}: give a file name ending in "
                                 + ", ".join("." + f for f in PLOT_FORMATS))
        check_output_path(args.plot, "plot file")
        if len(args.source) > 1:
            raise InputFileError("--plot draws one release; give one SOURCE with --plot")
    rig = read_rig(args.rig)
    # numba is the command's largest import: the kernels built ahead of time need none; until they are built,
    # they load in a helper process (numba) while this one loads the fit (scipy), on two cores
    from service.commands import kernels, native
    helper = native.load((rig.kind,)) or kernels.start((rig.kind,))
    try:
        status = _identify(args, rig, fmt, helper)
    finally:
        if helper is not None:
            from measurement.integrator import use_kernels
            use_kernels(None)
            helper.close()
    native.build_later((rig.kind,))  # for the next run, in the background
    return status


def _identify(args: argparse.Namespace, rig, fmt: str, helper) -> int:
    from measurement import Options, identify  # scipy: only when identifying
    from measurement.integrator import use_kernels
    from service.sources.dispatch import load_source

    if helper is not None:
        use_kernels(helper)
    traces = [load_source(s, camera=args.camera, rig=rig) for s in args.source]
    candidates = None
    if args.candidates is not None:
        candidates = tuple(c.strip() for c in args.candidates.split(",") if c.strip())
    options = Options(discover=not args.no_discover, candidates=candidates)
    if len(traces) > 1:
        from measurement.joint import identify_releases

        joint = identify_releases(traces, rig, options)
        print(joint.to_json() if args.json else joint.report())
        sys.stdout.flush()
        return 0
    result = identify(traces[0], rig, options)
    # the result first: a plot that cannot be written must not lose it
    if args.json:
        sys.stdout.write(result.to_json() + "\n")
    else:
        print(result.report())
    sys.stdout.flush()
    if args.plot:
        from service.publish.plot import render
        write_atomic(args.plot, render(result, fmt, dpi=110), "plot file")
        if not args.json:
            print(f"plot written to {args.plot}")
    return 0
