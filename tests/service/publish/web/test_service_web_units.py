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


def _payload(verdict: str, value: float | None, reasons: list[str], excluded: list[dict] | None = None) -> dict:
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


def _correlated_budget():
    """J = k/ω² − I0 with the stiffness and the tare fitted together (r = +0.98): alone, their lines' shares
    were 243.9 % beside a covariance of −176.3 %."""
    from measurement.uncertainty import Input, evaluate

    inputs = [Input("k", "stiffness (calibration)", 0.3651, 3.4e-4, "N·m/rad"),
              Input("I0", "tare inertia (calibration)", 0.002, 8e-6, "kg·m²"),
              Input("w", "ω_n (fit)", 5.0, 2e-4, "rad/s", kind="random")]
    return evaluate("J", "kg·m²", lambda x: x["k"] / x["w"] ** 2 - x["I0"], inputs, {("k", "I0"): 0.98})


def test_the_budgets_shares_are_never_negative_and_sum_to_100_percent():
    from service.publish.budget import budget_rows

    b = _correlated_budget()
    assert max(ln.share for ln in b.lines) > 1.0 and b.correlation_share < 0  # the raw GUM shares
    rows = budget_rows(b)
    assert [r.source for r in rows] == ["stiffness (calibration) and tare inertia (calibration), correlated "
                                        "(r = +0.980)", "stiffness (calibration)", "tare inertia (calibration)",
                                        "ω_n (fit)"]
    shares = [r.share for r in rows if r.share is not None]
    assert all(s >= 0 for s in shares) and sum(shares) == pytest.approx(100.0)
    assert [r.share is None for r in rows] == [False, True, True, False]
    # a reader checks each line by hand: c × u = c·u, in the page's unit
    for r in rows:
        c = r.sensitivity("g·cm²")
        if r.line is not None:
            assert c is not None and c * r.line.std == pytest.approx(r.contribution * 1e7)
    assert rows[1].per == " per N·m/rad" and rows[2].per == " per kg·m²"


def test_the_budget_on_the_page_and_in_the_pdf_gives_units_and_percent():
    import dataclasses

    from pypdf import PdfReader

    from measurement import Pendulum, Rig, identify, simulate_trace
    from service.publish.report import report_pdf

    env = _environment(Q.local_time)
    rig = Rig(kind="torsion", stiffness=0.3651, stiffness_std=3.4e-4, declared=("viscous",))
    result = identify(simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}}), theta0=0.25, duration=5,
                                     rate=100, noise_std=1e-4, seed=3), rig)
    result = dataclasses.replace(result, uncertainty_budget={"J": _correlated_budget()})
    html = env.get_template("_budget.html").render(r=result, unit="g·cm²")
    assert "g·cm² per N·m/rad" in html and "g·cm² per kg·m²" in html and "g·cm² per rad/s" in html
    percents = [float(x) for x in re.findall(r"</meter> ([\d.]+) %", html)]
    assert len(percents) == 2 and sum(percents) == pytest.approx(100.0, abs=0.2)
    assert "−" not in "".join(re.findall(r"</meter> [^<]* %", html)) and "correlated (r = +0.980)" in html
    payload = {**result.to_dict(), "recipe": None, "part": None, "release": None, "part_id": None}
    m = SimpleNamespace(seq=8, uuid="u-8", payload=payload, finished_at=1.7e9, trigger="web:olga", device_id="rig",
                        software_version="9", flags=())
    text = " ".join(p.extract_text() for p in PdfReader(io.BytesIO(report_pdf(m, None, "g·cm²"))).pages)
    text = " ".join(text.split())
    pdf_percents = [float(x) for x in re.findall(r"; ([\d.]+) % of u²", text)]
    assert pdf_percents == percents and "g·cm² per N·m/rad" in text and "of u_c²" not in text


def test_the_dfq_writes_local_time_and_an_invalid_parts_reason_in_its_unit(berlin):
    from service.publish.dfq import FIELD, dfq_text

    invalid = {**_payload("INVALID", None, ["release 1: " + TOO_WIDE, "standard uncertainty 2.3e-05 kg·m² above the "
                                             "limit 1e-05 kg·m²"]), "recipe": RECIPE}
    invalid["part"] = {**invalid["part"], "values": [0.01251, 0.01252, None]}
    ok = {**_payload("OK", 0.0125, []), "recipe": RECIPE}
    rows = [SimpleNamespace(payload=p, part_value=p["part"]["value"], finished_at=1.7e9 + 3600 * i,
                            part_verdict=p["part"]["verdict"], trigger="web:olga", device_id="rig",
                            part_id=f"SN-{i}", part_uuid=f"u-{i}") for i, p in enumerate((ok, invalid))]
    text = dfq_text(RECIPE, rows, "g·cm²")
    values = [ln.split(FIELD) for ln in text.split("\r\n") if FIELD in ln]
    # 1.7e9 s is 14.11.2023 22:13:20 UTC: the file says what the pages say, Berlin's time
    assert [v[2] for v in values] == ["14.11.2023/23:13:20", "15.11.2023/00:13:20"]
    assert Q.local_time(1.7e9, "%d.%m.%Y/%H:%M:%S") == values[0][2]
    assert values[1][1] == "255"
    assert values[1][7] == "verdict INVALID: release 1: invalid: standard uncertainty 2.3 g·cm² above the limit 1.0 g·cm²"
    assert "e-0" not in text and "kg·m²" not in text


def test_a_run_of_eight_is_named_western_electric_4_not_nelson_2():
    from measurement.spc import individuals

    s = individuals([10.0, 10.4, 9.6, 10.2, 9.8] + [10.05] * 8 + [9.9, 9.95])
    assert "run_of_8" in {v.rule for v in s.violations}
    said = [w for _name, words in Q.control_chart(s, "kg·m²")["rules"] for w in words if w.startswith("8 points")]
    assert said and all("(WE 4;" in w and "Nelson 2 asks for 9" in w for w in said)
    # the other rules keep their numbers in both books
    assert "(WE 1, Nelson 1)" in Q.RULE_WORDS["beyond_limits"] and "(Nelson 3)" in Q.RULE_WORDS["trend_of_6"]
    assert "(WE 2, Nelson 5)" in Q.RULE_WORDS["2_of_3_beyond_2sigma"]


def test_the_band_labels_its_limits_with_the_parts_decimals():
    band = Q.band(RECIPE, 0.0125, 2.3e-5, "g·cm²")
    assert band is not None and [t for _x, t in band["labels"]] == ["LSL 124000 g·cm²", "USL 126000 g·cm²"]
    four = Q.band({**RECIPE, "display_decimals": 4, "display_unit": "kg·m²"}, 0.0125, 2.3e-5, "kg·m²")
    assert four is not None and [t for _x, t in four["labels"]] == ["LSL 0.0124 kg·m²", "USL 0.0126 kg·m²"]


def test_the_history_writes_each_value_with_its_recipes_decimals():
    from service.publish.web.pages import Pages

    pages = object.__new__(Pages)  # the page context without a server: its recipe book and unit setting
    book = SimpleNamespace(recipes=[SimpleNamespace(name="wheel", display_decimals=1)])
    pages.app = SimpleNamespace(parts=SimpleNamespace(book=book))  # type: ignore[assignment]
    pages.server = SimpleNamespace(settings=SimpleNamespace(display_unit="kg·m²"))
    stored = {"recipe": {k: v for k, v in RECIPE.items() if k != "display_decimals"}}  # the payload has none
    assert pages.places(stored) == 1 and pages.places({"recipe": None}) == ".7g"
    env = _environment(Q.local_time)
    row = SimpleNamespace(uuid="u", seq=1, status="ok", part_verdict="OK", releases=1, release_index=1, verdict="OK",
                          J=0.01251234, J_std=2e-7, part_id="SN-1", recipe="wheel", finished_at=1.7e9, flags=(),
                          error=None, payload={**stored})
    html = env.get_template("history.html").render(rows=[row], total=1, page=1, pages=1, unit="kg·m²",
                                                   unit_of=pages.unit, places_of=pages.places, q={}, link=str,
                                                   export="", flag_names=[], recipes=["wheel"])
    assert "125123.4 g·cm²" in html
    # flags in words, the identifier their tooltip; the filter's options whole
    from measurement.flags import describe

    flagged = SimpleNamespace(**{**vars(row), "flags": ("model_ambiguous", "outliers_removed")})
    names = [("model_ambiguous", "model ambiguous", describe("model_ambiguous"))]
    html = env.get_template("history.html").render(rows=[flagged], total=1, page=1, pages=1, unit="kg·m²",
                                                   unit_of=pages.unit, places_of=pages.places, q={}, link=str,
                                                   export="", flag_names=names, recipes=["wheel"],
                                                   flag_meaning=describe, studied={})
    assert ">model ambiguous</span>, <span" in html and ">outliers removed</span>" in html
    assert 'title="model_ambiguous: ' in html and ">model_ambiguous<" not in html
    assert ">model ambiguous</option>" in html and "…" not in html.split('name="flag"')[1].split("</select>")[0]


def test_a_control_chart_writes_every_value_with_the_recipes_decimals_and_the_minus_sign():
    from measurement.spc import individuals

    s = individuals([0.01250028, 0.01249972, 0.01250061, 0.01249913, 0.01250007], usl=0.01251, lsl=0.01249)
    chart = Q.control_chart(s, "g·cm²", places=1)
    top = chart["top"]
    texts = [t for *_r, t in top["points"]] + [t.split(" ", 1)[1] for *_r, t in top["lines"]]
    texts += [t for _y, t in top["yticks"]]
    assert all(re.fullmatch(r"\d+\.\d", t) for t in texts), texts  # 125002.8, UCL 125007.9, LSL 124900.0 …
    assert any(t.startswith("LSL 124900.0") for *_r, t in top["lines"])
    below = Q.run_panel([-1.25, -1.5, -1.0], [("x_ref", -1.25, "centre")], places=2)
    assert [t for *_r, t in below["points"]] == ["−1.25", "−1.50", "−1.00"]
    assert Q.inertia(-8.69e-7, "g·cm²", 2) == "−8.69 g·cm²" and Q.inertia(8.69e-7, "g·cm²", 2) == "8.69 g·cm²"


def test_an_uncertainty_is_written_with_the_parts_decimals_never_as_zero():
    # U beside the value ± U: the same text (231.3, not 231 beside ± 231.3); a 1σ with the part's decimals too
    assert Q.spread(2.3134e-5, "g·cm²", 1) == "231.3 g·cm²" == Q.inertia(2.3134e-5, "g·cm²", 1)
    assert Q.spread(4.2e-6, "g·cm²", 1) == "42.0 g·cm²"
    assert Q.spread(2e-10, "g·cm²", 1) == "0.0020 g·cm²"  # two significant digits, not 0.0
    assert Q.reason("U = 2.3134e-05 kg·m² too large", "g·cm²", 1) == "U = 231.3 g·cm² too large"
