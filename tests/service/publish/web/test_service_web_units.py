"""Every number of a part in the part's own unit and decimals, the reasons of its verdict included (the tile,
the result page, the report and its PDF), rendered with the pages' own template environment."""

from __future__ import annotations

import io
import re
from types import SimpleNamespace

import pytest

from service.publish import quality as Q
from service.publish.web.pages import _environment

RECIPE = {"name": "wheel", "number": 3, "version": "v1", "nominal": 0.0125, "lower": 0.0124, "upper": 0.0126,
          "rule": "guard_band", "uncertain": "NOK", "coverage_factor": 2.0, "display_unit": "g·cm²",
          "display_decimals": 0}
#: what ``measurement.verdict`` writes: kg·m² with the digits a log keeps
OUTSIDE = "0.01271234 kg·m² above the upper limit 0.0126 kg·m²"
UNPROVEN = ("conformance not proven: 0.01259876 kg·m² with U = 2.3e-05 kg·m² reaches beyond [0.0124, 0.0126] kg·m² "
            "(guard band, ISO 14253-1)")
TOO_WIDE = "invalid: standard uncertainty 2.3e-07 kg·m² above the limit 1e-07 kg·m²"


def _payload(verdict: str, value: float, reasons: list[str], excluded: list[dict] | None = None) -> dict:
    part = {"verdict": verdict, "value": value, "U": 2.3e-05, "releases": 3, "used": [0, 1, 2], "quantity": "J",
            "values": [value] * 3, "excluded": excluded or [], "reasons": reasons, "zone": "nonconformance"}
    return {"recipe": RECIPE, "part": part, "release": None, "part_id": "SN-1006"}


def test_a_reason_is_written_in_the_unit_and_decimals_of_the_tile_above_it():
    assert Q.reason(OUTSIDE, "g·cm²", 0) == "127123 g·cm² above the upper limit 126000 g·cm²"
    assert Q.reason(UNPROVEN, "g·cm²", 0) == ("conformance not proven: 125988 g·cm² with U = 230 g·cm² reaches "
                                            "beyond [124000, 126000] g·cm² (guard band, ISO 14253-1)")
    # a small uncertainty keeps two significant digits rather than becoming 0
    assert Q.reason(TOO_WIDE, "g·cm²", 0) == "invalid: standard uncertainty 2.3 g·cm² above the limit 1.0 g·cm²"
    assert Q.reason(OUTSIDE, "kg·m²", 5) == "0.01271 kg·m² above the upper limit 0.01260 kg·m²"
    assert Q.reason("flag clipped", "g·cm²", 0) == "flag clipped" and Q.reason(None) == Q.MISSING


@pytest.mark.parametrize(("verdict", "value", "reasons", "shown"), [
    ("NOK", 0.01271234, [OUTSIDE], "127123 g·cm² above the upper limit 126000 g·cm²"),
    ("NOK", 0.01259876, [UNPROVEN], "with U = 230 g·cm² reaches beyond [124000, 126000] g·cm²"),
])
def test_the_result_page_and_the_tile_say_why_in_the_parts_unit(verdict, value, reasons, shown):
    env = _environment(Q.local_time)
    p = _payload(verdict, value, reasons, excluded=[{"index": 1, "reason": TOO_WIDE}])
    v = Q.part_view(p)
    html = env.get_template("_verdict.html").render(v=v, p=p, unit="g·cm²", band=None, why=None,
                                                    places=Q.places(RECIPE, "g·cm²", v["U"]))
    assert shown in html and "release 2 excluded</b>: invalid: standard uncertainty 2.3 g·cm²" in html
    assert "kg·m²" not in html and not re.search(r"\d\.\d{3,} g·cm²", html)
    tile = SimpleNamespace(part_verdict=verdict, uuid="u", part_id="SN-1006", finished_at=1.7e9)
    s = {"mode": "verdict", "tile": tile, "tile_view": v, "tile_unit": "g·cm²", "tile_places": 0, "why": None,
         "tile_band": None, "blocked": None, "repeat": False, "next_release": None}
    html = env.get_template("_now.html").render(s=s)
    assert shown in html and "kg·m²" not in html


def test_the_pdf_says_why_in_the_parts_unit():
    from pypdf import PdfReader

    from service.publish.report import report_pdf

    m = SimpleNamespace(seq=7, uuid="u-7", payload=_payload("NOK", 0.01271234, [OUTSIDE]), finished_at=1.7e9,
                        trigger="web:olga", device_id="rig", software_version="9", flags=())
    text = " ".join(p.extract_text() for p in PdfReader(io.BytesIO(report_pdf(m, None, "g·cm²", decimals=0))).pages)
    text = " ".join(text.split())
    assert "why: 127123 g·cm² above the upper limit 126000 g·cm²" in text
    assert "0.0127" not in text
