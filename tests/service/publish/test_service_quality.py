"""What the pages and the report say, as pure functions: display units, the tolerance band, the part view of
a payload and its typed result (never None or nan in words), the uncertainty budget's rows, the shift, the
control chart's geometry (violations marked, labels apart), a result plot's axes (what the sensor read)."""

from __future__ import annotations

import dataclasses
import datetime as dt
import math

import pytest

from measurement.spc import individuals
from measurement.units import INERTIA_UNITS, UnitError, from_si, inertia_unit
from service.publish import quality as Q
from service.publish.budget import BUDGET_FOOTNOTE, budget_rows
from service.publish.payload import stored_result


@pytest.fixture(scope="module")
def identified():
    """A result with its uncertainty budget (the stiffness stated with its σ), as a stored payload carries it."""
    from measurement import Pendulum, Rig, identify, simulate_trace

    rig = Rig(kind="torsion", stiffness=0.3651, stiffness_std=3.4e-4, declared=("viscous",))
    trace = simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}}), theta0=0.25, duration=5, rate=100,
                           noise_std=1e-4, seed=3)
    return identify(trace, rig)


def test_units_convert_from_si_exactly_and_unknown_ones_are_refused():
    assert from_si(1.0, "g·cm²") == pytest.approx(1e7) and from_si(1.0, "kg*mm^2") == pytest.approx(1e6)
    # 1 lb·in² = 0.45359237 kg · 0.0254² m²; 1 slug·ft² = 14.5939029 kg · 0.3048² m²
    assert from_si(0.45359237 * 0.0254**2, "lb·in²") == pytest.approx(1.0, rel=1e-12)
    assert from_si(14.593902937 * 0.3048**2, "slug*ft^2") == pytest.approx(1.0, rel=1e-9)
    assert set(INERTIA_UNITS) == {"kg·m²", "g·cm²", "kg·mm²", "lb·in²", "slug·ft²"}
    assert from_si(None, "g·cm²") is None and from_si(math.nan, "g·cm²") is None
    with pytest.raises(UnitError, match="expected one of kg·m²"):
        inertia_unit("furlong")
    assert Q.inertia(0.0125, "g·cm²") == "125000 g·cm²" and Q.inertia(None) == "–" and Q.inertia(math.inf) == "–"
    assert Q.number(None) == Q.number(math.nan) == Q.number(True) == "–"


def test_numbers_are_written_without_exponents_and_a_verdict_says_why(identified):
    # what pages used to show as 2.3e+02 and 8.42e+03, and sentences with exponents in them
    assert Q.inertia(2.3e-5, "g·cm²", ".2g") == "230 g·cm²" and Q.number(8420.3, ".3g") == "8420"
    assert Q.number(1.5e-7, ".2g") == "0.00000015" and Q.number(-0.25, "+.2g") == "-0.25" and Q.number(2, 3) == "2.000"
    assert Q.plain_text("u 9.3e-08 kg·m² above 1e-15, n 2.5E+03; id ab1e-5") == \
        "u 0.000000093 kg·m² above 0.000000000000001, n 2500; id ab1e-5"
    # a recipe's decimals: given, else those that resolve a hundredth of the tolerance; U with the value's
    recipe = {"nominal": 0.0125, "lower": 0.012375, "upper": 0.012625}
    assert Q.places(recipe, "g·cm²") == 0 and Q.places(recipe, "kg·m²") == 6
    assert Q.places({**recipe, "display_decimals": 2}, "g·cm²") == 2 and Q.places(None, "g·cm²", 2.3e-5) == 0
    why = Q.judgement({"recipe": recipe, "value": 0.0125 * 0.99 - 1e-9, "U": 2e-6}, "g·cm²")
    assert why is not None
    assert (why["deviation"], why["where"]) == ("−1.0 %", "below LSL")
    assert why["nominal"] == "125000 g·cm²" and why["limits"] == "123750 g·cm² … 126250 g·cm²"
    within = Q.judgement({"recipe": recipe, "value": 0.0125, "U": 2e-6}, "g·cm²")
    assert within is not None and within["where"] == "within the limits"
    assert Q.judgement({"recipe": {}, "value": 1.0}, "kg·m²") is None
    assert Q.local_time(None) == "–" and "T" not in Q.local_time(1.7e9) and Q.local_time(1.7e9, "%Y") == "2023"
    # a plot's title: the sensor that took the trace (a simulated rig said as such), J in the recipe's unit
    from types import SimpleNamespace
    m = SimpleNamespace(seq=7, payload={"recipe": {"display_unit": "g·cm²"}, "part_id": "SN-9"})
    filmed = dataclasses.replace(identified, acquisition={"camera": {}})
    assert Q.plot_labels(m, filmed, False) == ("g·cm²", "measurement #7, part SN-9, camera")
    assert Q.plot_labels(m, filmed, True, "kg·m²")[1] == "measurement #7, part SN-9, simulated rig"
    assert Q.plot_labels(m, None, False)[1] == "measurement #7, part SN-9, sensor"


def test_part_view_never_shows_a_release_verdict_as_the_parts():
    recipe = {"name": "r", "number": 1, "nominal": 1.0, "lower": 0.9, "upper": 1.1, "rule": "guard_band",
              "coverage_factor": 2.0, "display_unit": "g·cm²"}
    in_progress = {"recipe": recipe, "release": {"index": 1, "of": 2, "verdict": "OK", "value": 1.0, "U": 0.01,
                                                 "quantity": "J"}, "part": None, "verdict": None}
    v = Q.part_view(in_progress)
    assert (v["kind"], v["verdict"], v["index"], v["of"]) == ("release", None, 1, 2)
    done = {"recipe": recipe, "verdict": "INVALID", "part": {
        "verdict": "INVALID", "value": None, "U": None, "releases": 2, "used": [], "quantity": "J",
        "excluded": [{"index": 0, "reason": "invalid: x"}, {"index": 1, "reason": "invalid: y"}],
        "reasons": ["0 usable of 2 releases, fewer than 2", "release 1: invalid: x"]}}
    v = Q.part_view(done)
    assert v["verdict_words"] == "part INVALID (measure again)" and [e["release"] for e in v["excluded"]] == [1, 2]
    assert v["reasons"] == ["0 usable of 2 releases, fewer than 2"]  # the exclusions are said once
    assert Q.display_unit(done) == "g·cm²" and Q.display_unit({}, "lb*in^2") == "lb·in²"
    assert Q.part_view(None)["kind"] == "plain"


def test_tolerance_band_puts_the_guard_band_inside_the_limits_and_the_interval_around_the_value():
    b = Q.band({"nominal": 1.0, "lower": 0.9, "upper": 1.1, "rule": "guard_band"}, 1.05, 0.02)
    assert b is not None
    assert b["lsl"] < b["guard"][0] < b["nominal"] < b["guard"][1] < b["usl"]
    assert b["interval"][0] < b["value"] < b["interval"][1]
    simple = Q.band({"nominal": 1.0, "lower": 0.9, "upper": 1.1, "rule": "simple"}, 1.0, 0.02)
    assert simple is not None and simple["guard"] is None
    assert Q.band(None, 1.0, 0.1) is None
    far = Q.band({"nominal": 1.0, "lower": 0.9, "upper": 1.1}, 2.0, 0.01)
    assert far is not None and 0 <= far["lsl"] < far["usl"] < far["value"] <= far["width"]  # a value far out is still on the drawing


def test_the_budget_rows_are_each_lines_contribution_to_the_measurand(identified):
    stored = stored_result({**identified.to_dict(), "uuid": "u-1", "recipe": None})  # as a payload carries it
    assert stored is not None
    budget = stored.uncertainty_budget["J"]
    rows = budget_rows(budget)
    assert [r.source for r in rows] == [ln.source for ln in budget.lines] and len(rows) >= 2
    # its contribution to J in kg·m² (c·u carries the sign of its sensitivity), never the input's own u in the
    # input's unit
    k = next(r for r, ln in zip(rows, budget.lines) if ln.unit == "N·m/rad")
    line = next(ln for ln in budget.lines if ln.unit == "N·m/rad")
    assert k.contribution == line.contribution != line.std and k.share == pytest.approx(100 * line.share)
    assert sum(r.share or 0.0 for r in rows) == pytest.approx(100.0)
    assert budget_rows(None) == []
    # the part view of a plain result (no recipe) leads with J ± U and the budget of J
    v = Q.part_view({"recipe": None, "part": None, "release": None}, stored)
    assert (v["kind"], v["value"], v["U"], v["k"]) == ("plain", stored.J, stored.J_U, stored.coverage_factor)
    assert v["budget"] == rows
    assert Q.part_view({"recipe": None}, None)["budget"] == [], "a row of an older result schema: no budget shown"
    # a payload of an older result schema (an older release's row) reads as no result, a failed one too
    assert stored_result({**identified.to_dict(), "schema": 3}) is None and stored_result(None) is None


def test_a_row_the_previous_release_stored_reads_as_a_result_of_this_schema(identified):
    from measurement.result import SCHEMA_VERSION
    from service.publish.payload import _NEXT_SCHEMA

    assert max(_NEXT_SCHEMA) == SCHEMA_VERSION - 1, "a new result schema says how its previous one reads"
    added = _NEXT_SCHEMA[SCHEMA_VERSION - 1]
    previous = {k: v for k, v in identified.to_dict().items() if k not in added}
    read = stored_result({**previous, "schema": SCHEMA_VERSION - 1, "uuid": "u-1"})
    # what it held reads back as it was; the keys added since take the value every result had before them
    assert read is not None and read.to_dict() == {**identified.to_dict(), **added}


def test_shift_start_is_the_latest_start_at_or_before_now():
    tz = dt.timezone(dt.timedelta(hours=2))
    starts = ("06:00", "14:00", "22:00")
    assert Q.shift_start(starts, dt.datetime(2026, 3, 2, 15, 30, tzinfo=tz)).hour == 14
    early = Q.shift_start(starts, dt.datetime(2026, 3, 2, 3, 0, tzinfo=tz))
    assert (early.day, early.hour) == (1, 22)  # the night shift began yesterday


def test_control_chart_marks_violations_and_keeps_labels_apart():
    values = [1.0, 1.001, 0.999, 1.0005, 0.9995, 1.0, 1.0015, 0.999, 1.05]  # the last point far out
    s = individuals(values, 0.99, 1.01)
    names = [f"SN-{i}" for i in range(1, 10)]
    chart = Q.control_chart(s, "kg·m²", names=names)
    bad = [p for p in chart["top"]["points"] if p[2]]
    rules = dict(chart["rules"])
    # said in words, once per point (beyond the limits is one rule however found), the point by its name
    assert "SN-9" in [p[3] for p in bad] and rules["SN-9"][0] == "a point beyond the 3σ control limits (WE 1, Nelson 1)"
    assert len(rules["SN-9"]) == len(set(rules["SN-9"])) and len(rules) == len(chart["rules"])
    assert {p[3] for p in bad} <= set(rules)  # every marked point has its rule said
    # the moving range into the far point is beyond its UCL: marked on the MR chart and listed too
    mr_bad = [p[3] for p in chart["bottom"]["points"] if p[2]]
    assert mr_bad == ["SN-9"] and any("range beyond" in r for r in rules["SN-9"])
    # a range is never negative: neither is the range chart's axis
    assert all(float(text) >= 0 for _y, text in chart["bottom"]["yticks"])
    # a phone's chart: narrower, the same points
    narrow = Q.control_chart(s, "kg·m²", width=380.0, names=names)
    assert narrow["top"]["width"] == 380.0 and len(narrow["top"]["points"]) == 9 and narrow["rules"] == chart["rules"]
    ys = sorted(y for y, _kind, _text in chart["top"]["labels"])
    assert all(b - a >= 13.0 for a, b in zip(ys, ys[1:]))
    assert all(chart["top"]["top"] <= y - 4 <= chart["top"]["bottom"] for y in ys)
    texts = [t for _y, _k, t in chart["top"]["labels"]]
    assert len({t.split()[1] for t in texts}) == len(texts)  # each limit's value written distinguishably


def test_capability_has_a_confidence_interval_and_xbar_s_its_constants():
    from measurement.spc import c4, capability_interval, xbar_s

    assert c4(2) == pytest.approx(0.7979, abs=1e-4) and c4(10) == pytest.approx(0.9727, abs=1e-4)
    ci = capability_interval(1.33, 1.2, 7)
    cp, cpk = ci["cp"], ci["cpk"]
    assert cp is not None and cpk is not None
    assert cp[0] < 1.33 < cp[1] and cpk[0] < 1.2 < cpk[1]
    assert cp[1] - cp[0] > 1.0  # 7 values: too wide to decide on
    wide, narrow = capability_interval(1.33, 1.2, 7)["cp"], capability_interval(1.33, 1.2, 100)["cp"]
    assert wide is not None and narrow is not None
    assert narrow[1] - narrow[0] < (wide[1] - wide[0]) / 2
    s = xbar_s([[1.0, 2.0, 3.0], [2.0, 3.0, 4.0], [1.5, 2.5, 2.0]])
    assert s.chart == "Xbar-S" and s.range_lcl == 0.0 and s.ranges[0] == pytest.approx(1.0)
    assert Q.control_chart(s, "kg·m²")["range_name"] == "standard deviation (n = 3)"


def test_an_xbar_r_chart_draws_each_subgroup_and_its_range_in_the_display_unit():
    from measurement.spc import xbar_r

    groups = [[0.0125, 0.01251, 0.01249], [0.0125, 0.012505, 0.012495], [0.01251, 0.0125, 0.0125],
              [0.012495, 0.0125, 0.012505]]
    chart = Q.control_chart(xbar_r(groups, 0.0124, 0.0126), "g·cm²")
    assert chart["range_name"] == "range (n = 3)"
    assert len(chart["top"]["points"]) == len(chart["bottom"]["points"]) == 4
    # 0.0126 kg·m² in g·cm², far above the control limits: named, not drawn (it would flatten the chart)
    assert [t.split(" g·cm²")[0] for t in chart["off_chart"]] == ["USL 126000.0", "LSL 124000.0"]


def test_a_long_report_goes_on_to_more_pages_and_leaves_nothing_out(identified):
    import io
    from types import SimpleNamespace

    from pypdf import PdfReader

    from measurement.uncertainty import Line
    from service.publish.report import report_pdf

    n = 20
    recipe = {"name": "r", "number": 1, "version": "abc", "nominal": 0.0125, "lower": 0.012, "upper": 0.013,
              "rule": "guard_band", "uncertain": "NOK", "coverage_factor": 2.0}
    part = {"verdict": "OK", "value": 0.0125, "U": 1e-6, "releases": n, "used": list(range(n)), "quantity": "J",
            "values": [0.0125 + i * 1e-8 for i in range(n)], "excluded": [], "reasons": []}
    lines = tuple(Line(f"x{i}", f"source {i}", 1.0, 1e-7, "kg·m²", 1.0, 1e-7, 0.05, "random", math.inf, True, "")
                  for i in range(n))
    budget = dataclasses.replace(identified.uncertainty_budget["J"], lines=lines)
    result = dataclasses.replace(identified, uncertainty_budget={"J": budget})
    payload = {**result.to_dict(), "recipe": recipe, "part": part, "verdict": "OK", "part_id": "SN-9"}
    m = SimpleNamespace(seq=7, uuid="u-7", payload=payload, finished_at=1.7e9, trigger="web:olga",
                        device_id="rig", software_version="9", flags=())
    pages = [p.extract_text() for p in PdfReader(io.BytesIO(report_pdf(m, None, time_format="%d.%m.%Y"))).pages]
    text = " ".join(pages)
    assert "part OK" in text and "web:olga" in text
    assert f"release {n} of {n}" in text and f"source {n - 1}" in text  # the last lines too, on a later page
    # every page numbered "x of y" with the print date; the last one signed by who measured and who released
    import datetime as dt
    today = dt.date.today().strftime("%d.%m.%Y")
    assert len(pages) >= 2 and all(f"page {i} of {len(pages)} · printed {today}" in p for i, p in enumerate(pages, 1))
    assert "measured by" in pages[-1] and "released by quality" in pages[-1]
    assert "e-0" not in text and "e+0" not in text  # numbers without exponents


def test_the_verdict_block_shows_u_and_the_budget_partial_the_budget_when_the_result_has_one(identified):
    import jinja2

    from service.publish.web.pages import HERE

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(HERE / "templates")), autoescape=True)
    env.filters.update(fmt=Q.number, inertia=Q.inertia, iso=Q.iso, name=lambda v: v, plain=Q.plain_text,
                       reason=Q.reason)
    env.globals.update(VERDICT_WORDS=Q.VERDICT_WORDS, budget_rows=budget_rows, BUDGET_FOOTNOTE=BUDGET_FOOTNOTE)
    from measurement.uncertainty import Budget

    budget = Budget.from_dict({
        "measurand": "J", "value": 0.0125, "unit": "kg·m²", "U": 1.2e-7, "u": 6e-8, "u_random": 6e-8,
        "u_systematic": 0.0, "dof": None, "coverage_factor": 2.0, "correlations": [], "correlation_share": 0.0,
        "lines": [{"symbol": "omega_n", "source": "fit", "value": 5.4, "std": 2e-5, "unit": "rad/s",
                   "sensitivity": -0.0046, "contribution": -9e-8, "share": 0.6, "kind": "random", "dof": None,
                   "stated": True, "note": ""}]})
    plain = dataclasses.replace(identified, J=0.0125, J_std=5e-8, uncertainty_budget={"J": budget})
    p = {"recipe": None, "part": None, "release": None, "part_id": None}  # the payload's envelope
    html = env.get_template("_verdict.html").render(v=Q.part_view(p, plain), p=p, unit="g·cm²", band=None,
                                                    places=Q.places(None, "g·cm²", 1.2e-7))
    assert "± 1.2 g·cm² (U, k = 2)" in html and "None" not in html
    html = env.get_template("_budget.html").render(r=plain, unit="g·cm²")
    assert 'class="scroll"><table class="budget-table">' in html and "fit" in html  # scrolls in its card
    # in the page's unit, not kg·m² on a g·cm² page; the share second, where a phone still shows it
    assert "J = 125000 g·cm², U = 1.2 g·cm²" in html and "contribution c·u [g·cm²]" in html and "kg·m²" not in html
    assert html.index("share of u²") < html.index("contribution")
    before = dataclasses.replace(plain, uncertainty_budget={})  # a result without U or budget: its 1σ, said to be one
    html = env.get_template("_verdict.html").render(v=Q.part_view(p, before), p=p, unit="kg·m²", band=None,
                                                    places=Q.places(None, "kg·m²", 5e-8))
    # the value with the decimals of its uncertainty, never in e-notation
    assert "J = 0.012500000 kg·m² <span>± 0.000000050 kg·m² (standard uncertainty, 1σ)" in html
    assert env.get_template("_budget.html").render(r=before, unit="kg·m²").strip() == ""
    assert env.get_template("_budget.html").render(r=None, unit="kg·m²").strip() == ""


def test_each_of_the_six_orientations_of_a_tensor_set_is_drawn_differently_along_its_axis():
    from service.publish.web.drawing import axes_drawing, project

    r = 0.5 ** 0.5
    six = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1), "xy": (r, r, 0), "xz": (r, 0, r), "yz": (0, r, r)}
    drawn = {}
    for name, axis in six.items():
        (ax, ay), (bx, by) = axes_drawing(axis)["axis"]
        d = (bx - ax, ay - by)  # SVG's y points down
        p = project(axis)
        # along its own axis: the drawn line is the axis as seen from the view, in its direction
        assert abs(d[0] * p[1] - d[1] * p[0]) < 1e-2 * math.hypot(*d) * math.hypot(*p), name
        assert d[0] * p[0] + d[1] * p[1] > 0 and math.hypot(*d) > 40, name  # long enough to see
        drawn[name] = (d[0] / math.hypot(*d), d[1] / math.hypot(*d))
    for a in six:
        for b in six:
            if a < b:  # no two drawn parallel (xy once fell on z): at least 10° apart
                cos = abs(drawn[a][0] * drawn[b][0] + drawn[a][1] * drawn[b][1])
                assert cos < math.cos(math.radians(10)), (a, b)


@pytest.mark.parametrize(("reading", "unit"), [("angle", "rad"), ("rate", "rad/s")])
def test_a_plot_labels_its_axes_with_what_the_sensor_read(reading, unit):
    # a gyro's trace, fit and residuals are rates: "moi identify gyro.csv --plot" said "angle [rad]" over them
    import numpy as np

    from measurement import Pendulum, Rig, Trace, identify
    from measurement.identification import Options
    from service.publish.plot import figure

    rig = Rig(kind="torsion", stiffness=11.67)
    t = np.arange(0.0, 8.0, 0.005)
    theta, omega = Pendulum(rig, 0.27, {"viscous": {"c_per_J": 0.1}}).motion(t, 0.1)
    y = (theta if reading == "angle" else omega) + 1e-4 * np.random.default_rng(5).standard_normal(t.size)
    r = identify(Trace(t, y, source=f"{reading}.csv", quantity=reading), rig, Options(discover=False))
    assert r.measures == reading
    top, declared, final = figure(r).axes
    assert top.get_ylabel() == f"{reading} [{unit}]"
    assert declared.get_ylabel() == final.get_ylabel() == f"residual [{unit}]"
    for ax in (declared, final):
        assert ax.get_title(loc="left").endswith(f" {unit}")  # "...: RMS 0.0001 rad/s"
        legend = ax.get_legend()
        assert legend is not None and legend.get_texts()[0].get_text().endswith(f" {unit}")  # the noise floor's band
    assert final.get_xlabel() == "t [s]" and "ω_n = " in top.get_title() and top.get_title().endswith(" rad/s")
