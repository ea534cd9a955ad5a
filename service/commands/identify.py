"""`moi identify SOURCE --rig RIG.toml [--camera CAM.toml] [--json] [--plot FILE.png|.svg|.pdf]`."""

from __future__ import annotations

import argparse
import sys

from measurement.effects import EFFECTS
from service.errors import InputFileError
from service.sources.files import check_output_path, read_rig, write_atomic


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = formats_epilog()
    p.add_argument("source", metavar="SOURCE", nargs="+", help="one or more releases of one object (several are "
                   "identified jointly: shared physics, per-release offset and sensor terms, and a test that they "
                   "agree); each a trace CSV (t in s with angle in rad, or t with rate in rad/s: a gyro), a marker "
                   "track CSV (t in s, two markers' image positions ax, ay, bx, by in px: the camera's oblique view is "
                   "measured from their distance and removed), an export of another tool (below: a log with several "
                   "releases gives each), a video file or an image folder")
    p.add_argument("--rig", required=True, metavar="RIG.toml", help="rig file (kind, stiffness or mass/com_distance, declared effects)")
    p.add_argument("--camera", metavar="CAM.toml", help="camera file, for a video SOURCE")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the report")
    p.add_argument("--plot", metavar="FILE.png", help="write the trace, the fits and both residuals to a picture: "
                   "PNG, SVG or PDF by the file name's extension")
    g = p.add_argument_group("columns of an export (a label or a number from 1; recognised by name and unit when not given)")
    g.add_argument("--time-col", metavar="COL", help="the time column (s; ms by its unit)")
    g.add_argument("--angle-col", metavar="COL", help="the angle column (rad; degrees by its unit or --deg)")
    g.add_argument("--rate-col", metavar="COL", help="the angular rate column of a gyro (rad/s; °/s by its unit or --deg); "
                   "without it a three-axis gyro is read about the swing's own axis")
    g.add_argument("--xy", metavar="X,Y", help="two position columns of a tracked point (any length unit or pixels): the "
                   "angle about --pivot, or about the centre of the circle the track lies on; a single NAME takes "
                   "x_{NAME}, y_{NAME} (a Tracker project's track by its name)")
    g.add_argument("--pivot", metavar="PX,PY", help="the pivot's position in the units of --xy")
    g.add_argument("--deg", action="store_true", help="the angle or rate column is in degrees (or °/s)")
    p.add_argument("--release", type=int, metavar="N", help="identify only the N-th release found in the SOURCEs "
                   "(from 1, in the order the report lists them)")
    p.add_argument("--no-discover", action="store_true", help="fit the declared model only (no discovery loop)")
    p.add_argument("--candidates", metavar="NAMES",
                   help=f"comma-separated effects the loop may add (default: all of {', '.join(EFFECTS)})")


def formats_epilog() -> str:
    """The formats SOURCE may be in, one example each (from the readers' registry)."""
    from service.sources.formats.registry import describe

    lines = ["SOURCE formats, recognised by content (the first that fits):",
             "  moi CSV: t,angle (rad) or t,rate (rad/s), e.g. moi identify swing.csv --rig rig.toml"]
    lines += [f"  {name}: {what}\n      e.g. {example}" for name, what, example in describe()]
    return "\n".join(lines)


def columns(args: argparse.Namespace):
    """The user's naming of an export's columns."""
    from service.sources.formats.columns import ColumnChoice

    pivot = None
    if args.pivot is not None:
        try:
            px, py = (float(v) for v in args.pivot.split(","))
        except ValueError:
            raise InputFileError(f"--pivot {args.pivot!r}: expected two numbers PX,PY") from None
        pivot = (px, py)
    return ColumnChoice(args.time_col, args.angle_col, args.rate_col, args.xy, pivot, args.deg)


def run(args: argparse.Namespace) -> int:
    from service.publish.plot import PLOT_FORMATS

    fmt = args.plot.rsplit(".", 1)[-1].lower() if args.plot and "." in args.plot else ""
    if args.plot:  # a bad plot path is refused before the work, not after it
        if fmt not in PLOT_FORMATS:
            raise InputFileError(f"--plot {args.plot!r}: give a file name ending in "
                                 + ", ".join("." + f for f in PLOT_FORMATS))
        check_output_path(args.plot, "plot file")
        if len(args.source) > 1 and args.release is None:
            raise InputFileError("--plot draws one release; give one SOURCE, or --release N, with --plot")
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
    from service.sources.dispatch import load_releases

    if helper is not None:
        use_kernels(helper)
    choice = columns(args)
    traces = [tr for s in args.source for tr in load_releases(s, camera=args.camera, rig=rig, columns=choice)]
    if args.release is not None:
        if not 1 <= args.release <= len(traces):
            raise InputFileError(f"--release {args.release}: the SOURCEs hold {len(traces)} release(s); expected 1 to "
                                 f"{len(traces)}")
        traces = [traces[args.release - 1]]
    elif args.plot and len(traces) > 1:
        raise InputFileError(f"--plot draws one release; the SOURCE holds {len(traces)}: give --release N")
    candidates = None
    if args.candidates is not None:
        candidates = tuple(c.strip() for c in args.candidates.split(",") if c.strip())
    options = Options(discover=not args.no_discover, candidates=candidates)
    from measurement.reports import joint_report, result_report

    if len(traces) > 1:
        from measurement.joint import identify_releases

        joint = identify_releases(traces, rig, options)
        print(joint.to_json() if args.json else joint_report(joint))
        sys.stdout.flush()
        return 0
    result = identify(traces[0], rig, options)
    # the result first: a plot that cannot be written must not lose it
    if args.json:
        sys.stdout.write(result.to_json() + "\n")
    else:
        print(result_report(result))
    sys.stdout.flush()
    if args.plot:
        from service.publish.plot import render
        write_atomic(args.plot, render(result, fmt, dpi=110), "plot file")
        if not args.json:
            print(f"plot written to {args.plot}")
    return 0
