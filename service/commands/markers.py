"""`moi markers MARKERS.csv [--out TRACE.csv] [--as-seen]`: a trace CSV from two tracked markers.

The camera's oblique view is measured from the markers' constant distance and taken out of the
angle (``measurement.vision.marker_pair``); the trace's comment lines say what was measured.
"""

from __future__ import annotations

import argparse
import sys

from service.sources.files import read_markers, write_atomic


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("markers", metavar="MARKERS.csv",
                   help="marker track CSV: t (s) and two markers' image positions ax, ay, bx, by (px); a lost "
                        "marker's cells empty")
    p.add_argument("--out", metavar="TRACE.csv", help="write the trace here (default: standard output)")
    p.add_argument("--as-seen", action="store_true",
                   help="the angle as the image shows it: do not measure or correct the camera's view")


def run(args: argparse.Namespace) -> int:
    from measurement.vision.marker_pair import measure_view, pair_trace

    track = read_markers(args.markers)
    view = None if args.as_seen else measure_view(track.a, track.b)
    trace = pair_trace(track, view)
    lines = [f"swing angle from the marker pair in {args.markers}: the vector from marker a to marker b, "
             "rad from the image's +y axis towards +x",
             f"{len(trace)} samples; {track.missing} rows without both markers dropped"]
    if view is None:
        lines.append("camera view not measured (--as-seen): the angle as the image shows it")
    else:
        lines += view.report().splitlines()
        lines.append("the angle is corrected for that view: identify it with [sensor] calibrated = true in the rig "
                     "file")
    text = trace.to_csv(header_comment="\n".join(lines))
    if args.out:
        write_atomic(args.out, text, "trace")
        print("\n".join(lines))
        print(f"trace written to {args.out}")
    else:
        sys.stdout.write(text)
    return 0
