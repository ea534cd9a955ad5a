"""`moi spc [--recipe R] [--since DATE]`: control charts and capability of the parts measured per recipe.

For each recipe (or the one asked for) the completed parts in the store are
charted: X̄–R when every part combined the same number of releases (2 to 10),
else individuals / moving range of the part values; mean, σ (within and
overall), control limits, Cp/Cpk and Pp/Ppk against the recipe's tolerance,
points outside the limits and run rules (``measurement.spc``). INVALID parts
are left out and counted. A control-chart PNG is written per recipe.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from service.errors import InputFileError
from service.parts.recipes import recipe_spc
from service.publish.payload import fmt_time

from ._common import add_store_arguments, open_store, parse_time


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_store_arguments(p)
    p.add_argument("--recipe", "-r", metavar="NAME", help="only this recipe (default: every recipe in the store)")
    p.add_argument("--since", metavar="DATE", help="only parts finished at or after DATE (ISO 8601, UTC)")
    p.add_argument("--until", metavar="DATE", help="only parts finished before DATE")
    p.add_argument("--chart", choices=("auto", "I-MR", "Xbar-R"), default="auto",
                   help="chart type (default auto: X̄–R when every part has the same 2–10 releases, else I-MR)")
    p.add_argument("--out", metavar="DIR", default=".", help="directory of the chart PNGs spc-<recipe>.png (default .)")
    p.add_argument("--no-plot", action="store_true", help="do not write the PNGs")
    p.add_argument("--json", action="store_true", help="print JSON (with the plotted points)")


def run(args: argparse.Namespace) -> int:
    since = parse_time(args.since) if args.since else None
    until = parse_time(args.until) if args.until else None
    with open_store(args) as store:
        names = [args.recipe] if args.recipe else store.recipes()
        if not names:
            raise InputFileError(f"no parts measured with a recipe in {store.path}")
        results = {name: recipe_spc(store, name, since=since, until=until, chart=args.chart) for name in names}
    if args.recipe and results[args.recipe] is None:
        raise InputFileError(f"recipe {args.recipe!r}: fewer than 2 usable parts in the store"
                             + (f" since {args.since}" if args.since else ""))
    out_dir = Path(args.out)
    docs = []
    for name, spc in results.items():
        if spc is None:
            if not args.json:
                print(f"recipe {name}: fewer than 2 usable parts, no chart\n")
            continue
        png = None
        if not args.no_plot:
            from service.publish.plot import plot_control_chart
            out_dir.mkdir(parents=True, exist_ok=True)
            png = out_dir / f"spc-{name}.png"
            plot_control_chart(spc.summary, png, title=f"recipe {name} ({spc.quantity})")
        doc = spc.to_dict(include_points=True) | {"png": str(png) if png else None}
        docs.append(doc)
        if not args.json:
            print(f"recipe {name}: {len(spc.parts)} parts ({spc.quantity}), {fmt_time(spc.first)} … "
                  f"{fmt_time(spc.last)} UTC; INVALID parts left out: {spc.invalid_left_out}")
            if len(spc.versions) > 1:
                print(f"  note: the recipe changed during the series (versions {', '.join(spc.versions)})")
            print(spc.summary.report())
            if png:
                print(f"  chart written to {png}")
            print()
    if args.json:
        print(json.dumps(docs, indent=2, ensure_ascii=False))
    return 0
