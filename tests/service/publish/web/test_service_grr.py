"""The Gauge R&R from the appliance's own records: its page and PDF against an independent computation of the
same stored values (the ANOVA's sums of squares with numpy, here, not through ``measurement.gauge``), what an
unbalanced study lacks, the appraisers as operators or as appliances, each run's operator as the daemon records
it, and SPC's Cp/Cpk flagged when the recipe's gauge cannot tell its parts apart."""

from __future__ import annotations

import html
import io
import math
import re
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pytest

from service.core import vocabulary as V
from service.persistence.store import Store
from service.publish.payload import result_payload
from service.publish.web.pages import _environment
from tests.service.conftest import appliance_doc
from tests.service.publish.web.test_service_web import E_NOTATION, RAW, Client
from tests.service.publish.web.test_service_web_browser import browser  # noqa: F401  (the fixture)

ON = {"enabled": True}
#: g·cm² per kg·m² (the recipes below show their figures in g·cm²)
G_CM2 = 1e7
#: a part type with a wide tolerance (a good gauge for it) and one with a narrow one
DISC: dict[str, Any] = {"name": "disc", "number": 3, "version": "v1", "quantity": "J", "nominal": 0.0125, "lower": 0.0120,
        "upper": 0.0130}
RING: dict[str, Any] = {"name": "ring", "number": 4, "version": "v1", "quantity": "J", "nominal": 0.0125, "lower": 0.01249,
        "upper": 0.01251}


def _recipes(d: Path) -> Path:
    d.mkdir()
    for r, decimals in ((DISC, 1), (RING, 2)):
        (d / f"{r['name']}.toml").write_text(
            f'[recipe]\nname = "{r["name"]}"\nnumber = {r["number"]}\nnominal = {r["nominal"]}\n'
            f'tolerance = {r["upper"] - r["nominal"]:.6g}\nreleases = 1\ndisplay_unit = "g*cm^2"\n'
            f'display_decimals = {decimals}\n')
    return d


class Records:
    """Complete one-release parts written as the daemon writes them (the release completing the part)."""

    def __init__(self, store: Store, t0: float = 1.7e9) -> None:
        self.store, self.t = store, t0

    def part(self, recipe: dict, serial: str, value: float, trigger: str, device: str = "rig-1",
             verdict: str = "OK") -> None:
        self.t += 60.0
        part = {"mean": value, "U": 1e-6, "values": [value], "used": [0], "excluded": [], "quantity": "J",
                "reasons": [], "verdict": verdict}
        release = {"index": 1, "of": 1, "verdict": verdict, "value": value, "u_c": 5e-7, "quantity": "J",
                   "reasons": [], "part_uuid": f"pu-{self.t}"}
        result = {"J": value, "J_std": 5e-10, "flags": []}
        keys = {"part_id": serial, "recipe": recipe, "release": release, "part": part, "verdict": verdict}
        t = self.t

        def build(uuid: str, seq: int) -> dict[str, Any]:
            return result_payload(result, uuid=uuid, seq=seq, device_id=device, trigger=trigger, started_at=t,
                                  finished_at=t + 8, software_version="test", part=keys)

        self.store.record(status="ok", trigger=trigger, device_id=device, software_version="test", started_at=self.t,
                          finished_at=self.t + 8, result=result, build_payload=build,
                          part={"part_id": serial, "part_uuid": f"pu-{self.t}", "recipe": recipe["name"],
                                "recipe_version": "v1", "release_index": 1, "releases": 1, "verdict": verdict,
                                "part_verdict": verdict, "part_value": value, "part_U": 1e-6})

    def releases(self, recipe: dict, serial: str, values: Sequence[float], trigger: str) -> None:
        """One part of ``len(values)`` releases: the last one completes it with their mean."""
        n, mean = len(values), sum(values) / len(values)
        for i, value in enumerate(values, start=1):
            self.t += 60.0
            done = i == n
            release = {"index": i, "of": n, "verdict": "OK", "value": value, "quantity": "J", "reasons": []}
            keys = {"part_id": serial, "recipe": recipe, "release": release, "verdict": "OK" if done else None,
                    "part": {"mean": mean, "verdict": "OK", "quantity": "J"} if done else None}
            result, t = {"J": value, "flags": []}, self.t

            def build(uuid: str, seq: int, k: dict = keys, r: dict = result, t: float = t) -> dict[str, Any]:
                return result_payload(r, uuid=uuid, seq=seq, device_id="rig-1", trigger=trigger, started_at=t,
                                      finished_at=t + 8, software_version="test", part=k)

            self.store.record(status="ok", trigger=trigger, device_id="rig-1", software_version="test", started_at=t,
                              finished_at=t + 8, result=result, build_payload=build,
                              part={"part_id": serial, "recipe": recipe["name"], "release_index": i, "releases": n,
                                    "verdict": "OK", "part_verdict": "OK" if done else None,
                                    "part_value": mean if done else None})

    def study(self, recipe: dict, parts: Sequence[float], appraisers: Sequence[tuple[str, str, float]], trials: int,
              noise: float, seed: int, skip: Sequence[tuple[int, int, int]] = (), prefix: str = "SN") -> None:
        """parts × appraisers × trials, trial after trial as a study runs (each appraiser measures every part,
        then the next trial): appraisers (trigger, device, bias); skip: (part, appraiser, trial) not measured."""
        rng = np.random.default_rng(seed)
        for t in range(trials):
            for j, (trigger, device, bias) in enumerate(appraisers):
                for i, truth in enumerate(parts):
                    value = truth + bias + rng.normal(0.0, noise)
                    if (i, j, t) not in skip:
                        self.part(recipe, f"{prefix}-{i + 1}", value, trigger, device)


def expected(store: Store, recipe: str, tolerance: float, appraiser: str = "operator",
             parts: Sequence[str] | None = None) -> dict[str, Any]:
    """The study's figures computed here from the stored values: the two-way ANOVA's sums of squares with numpy,
    the AIAG MSA (4th ed.) components from them; values in g·cm²."""
    from scipy.stats import f as fisher

    rows = sorted(store.list(limit=None, recipe=recipe, parts_only=True), key=lambda m: m.seq)
    cells: dict[str, dict[str, list[float]]] = {}
    for m in rows:
        who = m.operator if appraiser == "operator" else m.device_id
        cells.setdefault(m.part_id, {}).setdefault(who, []).append(m.part_value * G_CM2)
    names = parts or list(cells)
    who = list(dict.fromkeys(a for p in names for a in cells[p]))
    x = np.array([[cells[p][a] for a in who] for p in names])
    p, a, r = x.shape
    grand = x.mean()
    ss_p = a * r * ((x.mean(axis=(1, 2)) - grand) ** 2).sum()
    ss_a = p * r * ((x.mean(axis=(0, 2)) - grand) ** 2).sum()
    ss_t = ((x - grand) ** 2).sum()
    ss_e = ((x - x.mean(axis=2, keepdims=True)) ** 2).sum()
    ss_i = ss_t - ss_p - ss_a - ss_e
    df_p, df_a, df_i, df_e = p - 1, a - 1, (p - 1) * (a - 1), p * a * (r - 1)
    ms_p, ms_a, ms_i, ms_e = ss_p / df_p, ss_a / df_a, ss_i / df_i, ss_e / df_e
    p_int = fisher.sf(ms_i / ms_e, df_i, df_e)
    pooled = p_int > 0.25
    if pooled:
        ms_e = ms_i = (ss_i + ss_e) / (df_i + df_e)
    ev2, int2 = ms_e, 0.0 if pooled else max(0.0, (ms_i - ms_e) / r)
    av2, pv2 = max(0.0, (ms_a - ms_i) / (p * r)), max(0.0, (ms_p - ms_i) / (a * r))
    grr = math.sqrt(ev2 + av2 + int2)
    tv = math.sqrt(ev2 + av2 + int2 + pv2)
    return {"ss": {"appraiser": ss_a, "part": ss_p, "appraiser × part": ss_i, "repeatability": ss_e, "total": ss_t},
            "df": {"appraiser": df_a, "part": df_p, "appraiser × part": df_i, "repeatability": df_e},
            "p_int": p_int, "pooled": pooled, "ev": math.sqrt(ev2), "av": math.sqrt(av2), "int": math.sqrt(int2),
            "grr": grr, "pv": math.sqrt(pv2), "tv": tv, "pct_process": 100 * grr / tv,
            "pct_tolerance": 100 * 6 * grr / (tolerance * G_CM2), "ndc": math.floor(1.41 * math.sqrt(pv2) / grr),
            "appraisers": who, "shape": (p, a, r), "x": x}


def _cells(page: str, row_id: str) -> list[str]:
    """The texts of a table row of the page (its header cell first)."""
    row = re.search(rf'<tr id="{re.escape(row_id)}">(.*?)</tr>', page, re.S)
    assert row is not None, f"no row {row_id} on the page"
    return [html.unescape(re.sub(r"<[^>]+>", "", c)).strip() for c in re.findall(r"<t[hd][^>]*>(.*?)</t[hd]>",
                                                                                 row.group(1), re.S)]


def _figure(page: str, key: str) -> str:
    found = re.search(rf'<dd id="{key}"[^>]*>(.*?)</dd>', page, re.S)
    assert found is not None, f"no figure {key} on the page"
    return html.unescape(re.sub(r"<[^>]+>", "", found.group(1)))


def _decimals(text: str) -> int:
    return len(text.split(".")[1]) if "." in text else 0


def _fill(state: Path) -> None:
    """disc: 5 parts × 3 appraisers (two named web users and the push button) × 2 trials, a good gauge for its
    tolerance, with a sixth part the button has not measured and the second user once only; and production parts
    measured once each. ring: 4 parts × 2 appraisers × 3 trials whose scatter is as large as the parts'."""
    parts = [0.01240, 0.01245, 0.01251, 0.01256, 0.01262]
    with Store(state) as store:
        rec = Records(store)
        for k in range(30):  # production: each part once
            rec.part(DISC, f"P-{k}", 0.0125 + 4e-5 * math.sin(k), "modbus")
        rec.study(DISC, parts + [0.01250], [("web:alice", "rig-1", 0.0), ("web:bob", "rig-1", 2e-7),
                                            ("button", "rig-1", -1e-7)], 2, 3e-7, seed=4,
                  skip=[(5, 2, 0), (5, 2, 1), (5, 1, 1)])
        rec.study(RING, [0.012500, 0.0125005, 0.0124995, 0.0125002], [("web:alice", "rig-1", 0.0),
                                                                       ("web:bob", "rig-1", 6e-7)], 3, 6e-7, seed=5,
                  prefix="R")


@pytest.fixture
def running(appliance_factory, tmp_path):
    _fill(tmp_path / "state")
    return appliance_factory(appliance_doc(tmp_path / "state", web=ON, recipes={
        "directory": str(_recipes(tmp_path / "recipes")), "active": "disc"}))


def test_the_page_matches_an_independent_computation_of_the_stored_values(running):
    c = Client(running.app.web.url)
    status, _, body = c.request("/grr")  # the active recipe
    page = body.decode()
    assert status == 200 and 'id="grr-verdict"' in page
    assert RAW.search(page) is None and E_NOTATION.search(page) is None
    store = running.app.store
    want = expected(store, "disc", DISC["upper"] - DISC["lower"], parts=[f"SN-{i}" for i in range(1, 6)])
    assert want["appraisers"] == ["alice", "bob", "button"] and want["shape"] == (5, 3, 2)
    facts = re.sub(r"<[^>]+>", " ", page.split('id="grr-facts"')[1].split("</dl>")[0])
    assert "5 parts × 3 appraisers × 2 trials" in facts and "operator: alice, bob, button" in facts
    # the ANOVA: df, SS and MS in (g·cm²)², four significant digits
    for source, key in (("appraiser", "appraiser"), ("part", "part"), ("appraiser × part", "appraiser-x-part"),
                        ("repeatability", "repeatability")):
        cells = _cells(page, f"anova-{key}")
        assert cells[0] == source and int(cells[1]) == want["df"][source]
        assert float(cells[2]) == pytest.approx(want["ss"][source], rel=1e-3)
        assert float(cells[3]) == pytest.approx(want["ss"][source] / want["df"][source], rel=1e-3)
    assert float(_cells(page, "anova-total")[2]) == pytest.approx(want["ss"]["total"], rel=1e-3)
    assert float(_cells(page, "anova-appraiser-x-part")[5]) == pytest.approx(want["p_int"], abs=6e-4)
    pooled = _figure_text(page, "grr-pooled")
    assert ("pooled into repeatability" in pooled) == want["pooled"] and ('id="anova-pooled"' in page) == want["pooled"]
    # the components: σ in g·cm² with one decimal more than the recipe's 1, % of TV and of the tolerance
    for key in ("ev", "av", "grr", "pv", "tv"):
        cells = _cells(page, f"components-{key}")
        assert _decimals(cells[3]) == 2 and float(cells[3]) == pytest.approx(want[key], abs=0.006), key
        assert float(cells[4]) == pytest.approx(6 * want[key], abs=0.006)
        assert float(cells[5]) == pytest.approx(100 * want[key] / want["tv"], abs=0.06)
    assert float(_figure(page, "pct-process").split(" %")[0]) == pytest.approx(want["pct_process"], abs=0.06)
    assert float(_figure(page, "pct-tolerance").split(" %")[0]) == pytest.approx(want["pct_tolerance"], abs=0.06)
    assert _figure(page, "ndc").startswith(str(want["ndc"]))
    band = "acceptable" if want["pct_tolerance"] < 10 else "conditional"
    assert f"· {band}" in _figure(page, "pct-tolerance")
    # the values: the recipe's unit and its decimals
    values = _cells(page, "grr-values-SN-1")
    assert values[0] == "SN-1" and all(_decimals(v) == 1 for v in values[1:])
    assert [float(v) for v in values[1:-1]] == pytest.approx(list(want["x"][0].ravel()), abs=0.051)
    assert "kg·m²" not in page.split('id="grr-verdict"')[1]


def _figure_text(page: str, element: str) -> str:
    found = re.search(rf'id="{element}">(.*?)</', page, re.S)
    assert found is not None
    return html.unescape(found.group(1))


def test_an_unbalanced_study_says_what_is_missing_and_production_parts_stay_out(running):
    c = Client(running.app.web.url)
    page = c.request("/grr?recipe=disc")[2].decode()
    lacking = re.sub(r"<[^>]+>", "", page.split('id="grr-lacking"')[1].split("</section>")[0])
    assert "SN-6: bob: lacks 1 of the 2 trials; button: lacks all 2 trials" in html.unescape(lacking)
    assert "SN-1" not in lacking  # complete
    assert _cells(page, "grr-counts-SN-6") == ["SN-6", "2", "1 of 2", "0 of 2", "lacks trials"]
    notes = html.unescape(page.split('id="grr-notes"')[1].split("</ul>")[0])
    assert "30 parts measured only once (production, not a study): left out" in notes
    # three trials asked for: no part has them, no figures, and why
    page = c.request("/grr?recipe=disc&trials=3")[2].decode()
    assert 'id="anova"' not in page
    assert "needs at least 2 parts measured 3 times by each of alice, bob, button; 0 are complete" in html.unescape(page)
    # without the button: the sixth part lacks only bob's second trial
    page = c.request("/grr?recipe=disc&appraiser=alice&appraiser=bob")[2].decode()
    assert "SN-6: bob: lacks 1 of the 2 trials" in html.unescape(page) and "5 parts × 2 appraisers × 2 trials" in page
    assert c.request("/grr?recipe=disc&by=person")[0] == 400 and c.request("/grr?trials=1")[0] == 400
    status, _, body = c.request("/grr?recipe=rotor&since=2020-01-01")  # no records: said, no figures
    assert status == 200 and "no Gauge R&amp;R yet: no measurements of this recipe in the period" in body.decode()


def test_the_pdf_says_what_the_page_says(running):
    from pypdf import PdfReader

    c = Client(running.app.web.url)
    page = c.request("/grr?recipe=ring")[2].decode()
    status, headers, body = c.request("/grr/report.pdf?recipe=ring", timeout=180)
    assert status == 200 and headers["Content-Type"] == "application/pdf" and "ring-gauge-rr.pdf" in \
        headers["Content-Disposition"]
    text = " ".join(" ".join(p.extract_text() for p in PdfReader(io.BytesIO(body)).pages).split())
    want = expected(running.app.store, "ring", RING["upper"] - RING["lower"])
    shown = _figure(page, "pct-process").split(" · ")[0]
    assert float(shown.split(" %")[0]) == pytest.approx(want["pct_process"], abs=0.06)
    assert f"%GRR of the process variation (100·GRR/TV): {shown}" in text
    assert "4 parts × 2 appraisers × 3 trials" in text and "g·cm²" in text and "kg·m²" not in text
    assert "page 1 of" in text and "accepted by quality" in text
    status, _, body = c.request("/grr/report.pdf?recipe=rotor", timeout=180)  # no study yet: the PDF says why
    assert status == 200 and "no measurements of this recipe" in PdfReader(io.BytesIO(body)).pages[0].extract_text()


def test_the_appliances_of_a_fleet_as_the_appraisers(tmp_path):
    from service.parts.gauge_rr import recipe_grr

    with Store(tmp_path / "s") as store:
        rec = Records(store)
        # the same operator on two appliances, the second reading 1 g·cm² higher
        rec.study(DISC, [0.01240, 0.01250, 0.01260], [("web:alice", "rig-1", 0.0), ("web:alice", "rig-2", 1e-7)], 2,
                  2e-8, seed=9)
        by_operator = recipe_grr(store, "disc")
        by_device = recipe_grr(store, "disc", by="device")
        want = expected(store, "disc", 0.001, appraiser="device")
    assert by_operator.study is None and by_operator.appraisers == ("alice",)
    assert "at least 2 appraisers" in (by_operator.why or "")
    assert by_device.study is not None and by_device.appraisers == ("rig-1", "rig-2")
    assert by_device.study.av * G_CM2 == pytest.approx(want["av"], rel=1e-6)
    assert by_device.study.grr * G_CM2 == pytest.approx(want["grr"], rel=1e-6)


def test_a_trial_may_be_each_release(tmp_path):
    """Parts of two releases, each measured once by each appraiser: as parts, one trial each (no study); as
    releases, two trials each, the releases' values."""
    from service.parts.gauge_rr import recipe_grr

    rng = np.random.default_rng(11)
    values: dict[str, dict[str, list[float]]] = {}
    with Store(tmp_path / "s") as store:
        rec = Records(store)
        for who in ("alice", "bob"):
            for k, truth in enumerate((0.01240, 0.01250, 0.01260)):
                pair = [truth + rng.normal(0.0, 3e-7) for _ in range(2)]
                values.setdefault(f"SN-{k}", {})[who] = pair
                rec.releases(DISC, f"SN-{k}", pair, V.web_source(who))
        as_parts = recipe_grr(store, "disc")
        as_releases = recipe_grr(store, "disc", trial="release")
    assert as_parts.study is None and as_parts.single == 0 and as_parts.trials == 1
    assert "at least 2 trials" in (as_parts.why or "")
    s = as_releases.study
    assert s is not None and (s.parts, s.appraisers, s.trials) == (("SN-0", "SN-1", "SN-2"), ("alice", "bob"), 2)
    x = np.array([[values[p][a] for a in ("alice", "bob")] for p in ("SN-0", "SN-1", "SN-2")])
    ss_e = float(((x - x.mean(axis=2, keepdims=True)) ** 2).sum())
    assert next(r.ss for r in s.anova if r.source == "repeatability") == pytest.approx(ss_e, rel=1e-9)


def test_spc_flags_cp_and_cpk_when_the_gauge_cannot_tell_the_parts_apart(running):
    c = Client(running.app.web.url)
    ring = c.request("/spc?recipe=ring")[2].decode()
    want = expected(running.app.store, "ring", RING["upper"] - RING["lower"])
    assert want["pct_process"] > 30 or want["ndc"] < 5
    warning = html.unescape(re.sub(r"<[^>]+>", "", ring.split('id="gauge-warning"')[1].split("</dd>")[0]))
    assert "Cp and Cpk above are not meaningful" in warning and "4 parts × 2 appraisers × 3 trials" in warning
    assert f"the gauge's %GRR is {want['pct_process']:.3g} % of the process variation" in warning
    assert 'href="/grr?recipe=ring"' in ring
    disc = c.request("/spc?recipe=disc")[2].decode()
    assert 'id="capability"' in disc and 'id="gauge-warning"' not in disc  # a good gauge for its tolerance


def test_each_run_records_its_operator(running):
    app = running.app
    before = app.store.count()
    app.command(V.TRIGGER, V.web_source("olga"))  # as the web page's session names a logged-in user
    running.wait_done(1)
    running.press()  # the push button
    running.wait_done(2)
    new = sorted(app.store.list(limit=2), key=lambda m: m.seq)
    assert app.store.count() == before + 2
    assert [(m.trigger, m.operator) for m in new] == [("web:olga", "olga"), ("button", "button")]


@pytest.mark.parametrize(("role", "shown"), [("quality", True), ("admin", True), ("operator", False), (None, False)])
def test_the_menu_offers_the_gauge_rr_to_quality_and_admin(role, shown):
    env = _environment(lambda ts: "")
    page = env.get_template("base.html").render(role=role, logged_in=role is not None, csrf="x", path="/")
    assert ('href="/grr"' in page) == shown


@pytest.mark.browser
def test_the_page_fits_a_phone_and_a_desktop(running, browser):  # noqa: F811 (the fixture imported above)
    """The Gauge R&R page at 390 and 1280 px: its tables scroll inside their card, nothing wider than the window;
    no e-notation; the verdict on screen. Screenshots in $MOI_ARTIFACTS when set."""
    import os

    from selenium.webdriver.common.by import By

    url = running.app.web.url.rstrip("/")
    artifacts = os.environ.get("MOI_ARTIFACTS")
    for width in (390, 1280):
        browser.set_window_size(width, 900)
        for recipe in ("disc", "ring"):
            browser.get(f"{url}/grr?recipe={recipe}")
            inner = browser.execute_script("return window.innerWidth")
            assert browser.execute_script("return document.documentElement.scrollWidth") <= inner, (recipe, width)
            verdict = browser.find_element(By.ID, "grr-verdict")
            assert verdict.is_displayed() and verdict.rect["x"] + verdict.rect["width"] <= inner
            assert E_NOTATION.search(browser.find_element(By.TAG_NAME, "body").text) is None
            assert len(browser.find_elements(By.TAG_NAME, "h1")) == 1
            if artifacts:
                browser.save_screenshot(str(Path(artifacts) / f"grr-{recipe}-{width}.png"))


def test_a_study_far_below_the_manual_s_design_of_parts_all_alike_says_so(tmp_path, appliance_factory):
    """3 parts all alike × 2 appraisers × 2 trials: the figures are said to be indicative, %GRR of the process and
    ndc meaningless (PV ≈ 0), the verdict is %GRR of the tolerance's; SPC does not call Cp/Cpk meaningless on
    it, and the PDF says what the page says."""
    from pypdf import PdfReader

    with Store(tmp_path / "state") as store:
        rec = Records(store)
        for e in (3e-7, -3e-7):  # every part's and appraiser's mean the same: PV = 0
            for who in ("web:alice", "web:bob"):
                for i in range(3):
                    rec.part(DISC, f"SN-{i + 1}", 0.0125 + (e if i != 1 or who == "web:bob" else -e), who)
    running = appliance_factory(appliance_doc(tmp_path / "state", web=ON, recipes={
        "directory": str(_recipes(tmp_path / "recipes")), "active": "disc"}))
    c = Client(running.app.web.url)
    page = html.unescape(c.request("/grr?recipe=disc")[2].decode())
    want = expected(running.app.store, "disc", DISC["upper"] - DISC["lower"])
    assert want["pv"] < 0.1 * want["tv"]  # the parts do not span the process
    verdict = re.sub(r"<[^>]+>", "", page.split('id="grr-verdict"')[1].split("</div>")[0])
    band = "acceptable" if want["pct_tolerance"] < 10 else "conditional"
    assert f"Gauge R&R {band}" in verdict and "of the tolerance" in verdict and "indicative" in verdict
    assert "ndc" not in verdict and "process variation" not in verdict
    cautions = re.findall(r'class="fault grr-caution">(.*?)</p>', page, re.S)
    assert len(cautions) == 2
    assert "3 parts × 2 appraisers × 2 trials" in cautions[0] and "10 parts spanning the process" in cautions[0]
    assert "2–3 appraisers, 2–3 trials" in cautions[0] and "indicative" in cautions[0]
    assert "the parts do not span the process" in cautions[1] and "%GRR of the tolerance" in cautions[1]
    assert "meaningless" in _figure(page, "pct-process") and "·" not in _figure(page, "pct-process")
    assert "meaningless" in _figure(page, "ndc") and "cannot tell" not in _figure(page, "ndc")
    spc = c.request("/spc?recipe=disc")[2].decode()
    assert 'id="capability"' in spc and 'id="gauge-warning"' not in spc and "not meaningful" not in spc
    text = " ".join(" ".join(p.extract_text() for p in PdfReader(io.BytesIO(
        c.request("/grr/report.pdf?recipe=disc", timeout=180)[2])).pages).split())
    assert "far below the AIAG MSA design" in text and "do not span the process" in text


def test_capability_warnings_hedge_a_small_study_and_drop_the_figures_against_pv():
    from measurement.gauge import capability_warnings, gauge_rr
    from measurement.grr_design import adequate, below_design, cautions

    rng = np.random.default_rng(3)
    truths = np.linspace(0.0124, 0.0126, 10)
    big = gauge_rr([[[t + rng.normal(0, 4e-5) for _ in range(3)] for _ in range(3)] for t in truths], tolerance=1e-3)
    assert adequate(big) and below_design(big) is None and cautions(big) == ()
    assert any(w.figure == "%GRR of the process" for w in capability_warnings(grr=big))
    assert not any("indicative" in w.message for w in capability_warnings(grr=big))
    small = gauge_rr([[[t + rng.normal(0, 3e-6) for _ in range(2)] for _ in range(2)] for t in truths[:4]],
                     tolerance=2e-5)
    warnings = capability_warnings(grr=small)
    assert warnings and all("indicative: 4 parts × 2 appraisers × 2 trials" in w.message for w in warnings)
    alike = gauge_rr([[[0.0125 + rng.normal(0, 3e-7) for _ in range(2)] for _ in range(2)] for _ in range(3)],
                     tolerance=1e-3)
    assert not adequate(alike) and len(cautions(alike)) == 2
    assert capability_warnings(grr=alike) == ()  # its %GRR of the tolerance is small; those against PV say nothing
