"""`moi report ID --pdf FILE`: the quality record of one measurement as a PDF (what the web page's report
shows: verdict and decision rule, J ± U with its coverage factor, the releases with their flags, the
evidence plot, calibration, software version, operator, time)."""

from __future__ import annotations

import argparse

from measurement.units import SI, inertia_unit
from service.errors import InputFileError
from service.sources.files import check_output_path, write_atomic

from ._common import add_store_arguments, open_store


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("id", metavar="ID", help="UUID, UUID prefix or sequence number of the measurement")
    add_store_arguments(p)
    p.add_argument("--pdf", required=True, metavar="FILE.pdf", help="write the report to this PDF file")
    p.add_argument("--unit", metavar="UNIT", help="unit of inertia shown when the recipe names none "
                   "(kg·m², g·cm², kg·mm², lb·in², slug·ft²; default kg·m²)")


def run(args: argparse.Namespace) -> int:
    from service.publish.quality import display_unit
    from service.publish.report import report_pdf
    from service.publish.web.settings import PLOT_NAME

    if not args.pdf.lower().endswith(".pdf"):
        raise InputFileError(f"--pdf {args.pdf!r}: give a file name ending in .pdf")
    check_output_path(args.pdf, "report file")
    default = inertia_unit(args.unit) if args.unit else SI  # an unknown unit: one line, exit 2
    with open_store(args) as store:
        m = store.get(args.id)
        if m is None:
            raise InputFileError(f"no single measurement matches {args.id!r} in {store.path}")
        got = store.get_attachment(m.uuid, PLOT_NAME)
        pdf = report_pdf(m, got[0] if got else None, display_unit(m.payload, default), store.get)
    write_atomic(args.pdf, pdf, "report file")
    print(f"report of measurement #{m.seq} ({m.uuid}) written to {args.pdf}")
    return 0
