"""The Type 1 gauge study run through its web page on the simulated rig: started by the quality engineer with x_ref
and T in the recipe's display unit, refused with the reason, counted k of n, aborted, and its page, its PDF and
SPC's capability giving figures equal to an independent computation (numpy, scipy's t) of the stored J values."""

from __future__ import annotations

import datetime as dt
import io
import math
import re
from html import unescape
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from service.publish.web.auth import allowed
from tests.service.conftest import appliance_doc, wait_until
from tests.service.publish.web import test_service_web_browser as in_browser
from tests.service.publish.web.test_service_web import Client

browser = in_browser.browser  # the headless Chromium session fixture (skipped, or failed under CI, without it)
G_CM2 = 1e7  # g·cm² per kg·m²
J_REF, T = 0.0125, 5e-4  # kg·m²: the simulated part, and ± 2 % of it


def _doc(tmp_path):
    fresh = (dt.date.today() - dt.timedelta(days=30)).isoformat()
    rig = tmp_path / "rig.toml"
    rig.write_text(f'[rig]\nkind = "torsion"\nstiffness = 0.3651\n[calibration]\ndate = {fresh}\nvalid_days = 365\n')
    (tmp_path / "old-rig.toml").write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n[calibration]\n'
                                           'date = 2020-01-15\nvalid_days = 365\n')
    recipes = tmp_path / "recipes"
    recipes.mkdir()
    (recipes / "old.toml").write_text('[recipe]\nname = "old"\nnumber = 2\nnominal = 0.0125\ntolerance_percent = 2.0\n'
                                      'rig = "../old-rig.toml"\n')
    (recipes / "ref.toml").write_text('[recipe]\nname = "ref"\nnumber = 1\nnominal = 0.0125\ntolerance_percent = 2.0\n'
                                      'releases = 1\ndisplay_unit = "g·cm²"\ndisplay_decimals = 1\n')
    return appliance_doc(tmp_path / "state", device={"rig": str(rig)}, web={"enabled": True},
                         recipes={"directory": str(recipes), "active": "ref"})


def _client(app):
    c = Client(app.web.url)
    token = Path(app.web.token_file).read_text().strip()
    auth = {"Authorization": f"Bearer {token}", "Origin": c.base}
    return c, auth


def _start(c, auth, **form):
    form = {"reference": f"{J_REF * G_CM2:g}", "tolerance": f"{T * G_CM2:g}".replace(".", ","), "count": "25",
            "part_id": "CS-1"} | form
    return c.json("/api/type1/start", data=form, method="POST", headers=auth)


def _measure_until(running, counted, presses: int = 0) -> int:
    """Press Measure until ``counted(app)`` holds; returns the presses so far. On a loaded machine the simulated rig
    may abort a run (no sample in time): it is stored as aborted and counts for nothing, so it is measured again."""
    app = running.app
    while not app.call_soon(lambda: counted(app)).result(10):
        assert presses < 60, "too many runs without a counted release"
        presses += 1
        running.press()
        running.wait_done(presses)
    return presses


def _done(n: int):
    return lambda app: (app.study_progress() or {}).get("done", 0) >= n


def _ok(store):
    return [m for m in store.list(limit=None) if m.status == "ok"]


def _text(html: str, id_: str) -> str:
    m = re.search(rf'id="{re.escape(id_)}"[^>]*>(.*?)</', html, re.S)
    assert m, id_
    return unescape(m.group(1)).strip()


def test_a_study_through_the_page_gives_the_figures_of_an_independent_computation(tmp_path, appliance_factory):
    running = appliance_factory(_doc(tmp_path))
    app = running.app
    c, auth = _client(app)
    # refused, each with why: not logged in, too few, no tolerance
    assert c.json("/api/type1/start", data={"count": "25"}, method="POST")[0] == 401
    status, body = _start(c, auth, count="24")
    assert status == 400 and "at least 25 measurements" in body["error"]
    status, body = _start(c, auth, tolerance="")
    assert status == 400 and "no tolerance" in body["error"]
    assert _start(c, auth) == (200, {"accepted": True, "command": "type1", "status": "done"})
    status, body = _start(c, auth)
    assert status == 409 and "a Type 1 study of ref runs (0 of 25)" in body["error"]
    page = c.request("/type1")[2].decode()
    assert _text(page, "t1-count") == "0 of 25" and 'id="measure"' in page
    presses = _measure_until(running, _done(12))
    assert c.json("/api/type1")[1]["study"]["done"] == 12 and _text(c.request("/type1")[2].decode(),
                                                                      "t1-count") == "12 of 25"
    running_page = c.request("/type1")[2].decode()  # what was entered, in the recipe's unit and decimals
    assert _text(running_page, "t1-plan-reference") == "125000.0 g·cm²"
    assert _text(running_page, "t1-plan-tolerance") == "5000.0 g·cm²"
    presses = _measure_until(running, _done(25), presses)
    state = c.json("/api/type1")[1]
    assert state["study"]["status"] == "complete"
    rec = state["latest"]
    assert rec["status"] == "complete" and rec["part_id"] == "CS-1" and len(rec["releases"]) == 25
    assert rec["reference"] == pytest.approx(J_REF, rel=1e-12) and rec["tolerance"] == pytest.approx(T, rel=1e-12)
    # the independent computation, from the stored J of the linked releases
    store = app.store
    x = np.array([store.get(u).J for u in rec["releases"]])
    assert {m.uuid for m in _ok(store)} == set(rec["releases"]) and not any(m.part_verdict for m in store.list())
    s, mean = x.std(ddof=1), x.mean()
    bias = mean - J_REF
    cg, cgk = 0.2 * T / (6 * s), (0.1 * T - abs(bias)) / (3 * s)
    t = bias / (s / math.sqrt(25))
    p = 2 * stats.t.sf(abs(t), 24)
    assert rec["study"]["cg"] == pytest.approx(cg, rel=1e-9) and rec["study"]["cgk"] == pytest.approx(cgk, rel=1e-9)
    # the page: every number in the recipe's unit (g·cm²) and decimals (1; a scatter one more)
    html = c.request(f"/type1/{rec['uuid']}")[2].decode()
    assert _text(html, "t1-cg") == f"{cg:.2f} ({'≥' if cg >= 1.33 else '<'} 1.33)"
    assert _text(html, "t1-cgk") == f"{cgk:.2f} ({'≥' if cgk >= 1.33 else '<'} 1.33)"
    assert _text(html, "t1-mean") == f"{mean * G_CM2:.1f} g·cm²"
    assert _text(html, "t1-s") == f"{s * G_CM2:.2f} g·cm²"
    assert _text(html, "t1-reference") == f"{J_REF * G_CM2:.1f} g·cm²" and _text(html, "t1-tolerance") == "5000.0 g·cm²"
    assert _text(html, "t1-bias").startswith(f"{bias * G_CM2:.2f} g·cm² (95 % interval".replace("-", "−"))
    assert "-" not in _text(html, "t1-bias")  # the minus sign, as everywhere
    assert _text(html, "t1-ttest").startswith(f"t = {t:.2f}, 24 degrees of freedom, p = {float(f'{p:.3g}'):g}")
    assert ("not significant" in _text(html, "t1-ttest")) == (p >= 0.05)
    assert _text(html, "t1-tmin") == f"{1.33 * 6 * s / 0.2 * G_CM2:.1f} g·cm²"
    verdict = "capable" if cg >= 1.33 and cgk >= 1.33 else "not capable"
    assert _text(html, "t1-verdict").startswith(verdict)
    assert 'id="t1-chart"' in html and html.count('class="point') == 2 * 25  # the run chart at both widths
    # a flagged release marked on the chart and named in the list (its flags in words, the identifier its title)
    flagged = [store.get(u).flags for u in rec["releases"]]
    assert html.count('class="point violation"') == 2 * sum(1 for f in flagged if f)
    for f in {f for fl in flagged for f in fl}:
        assert f'title="{f}">{f.replace("_", " ")}<' in html
    ticks = re.findall(r'class="tick" text-anchor="end">([^<]*)<', html)
    assert ticks and all(re.fullmatch(r"\d+\.\d", t) for t in ticks), ticks  # the axis in the recipe's decimals
    # linked to its measurements, each stored with the reference's part ID and the recipe, without a part verdict
    assert all(f'href="/results/{u}"' in html for u in rec["releases"])
    assert c.request(f"/results/{rec['releases'][0]}")[0] == 200
    assert {(m.part_id, m.recipe, m.part_verdict) for m in _ok(store)} == {("CS-1", "ref", None)}
    # the PDF says the same
    status, headers, pdf = c.request(f"/type1/{rec['uuid']}/report.pdf", timeout=180)
    assert status == 200 and pdf[:5] == b"%PDF-" and headers["Content-Type"] == "application/pdf"
    from pypdf import PdfReader

    text = "".join(pg.extract_text() for pg in PdfReader(io.BytesIO(pdf)).pages)
    assert f"{cg:.2f}" in text and f"{mean * G_CM2:.1f} g·cm²" in text and "run chart" in text
    assert all(f"{v * G_CM2:.1f} g·cm²" in text for v in x)  # the n values listed
    assert "with 1 decimal; s, the bias and its interval with one more" in _text(html, "t1-decimals") and \
        "with 1 decimal; s, the bias" in text
    # History and the release's page say which study counted it, and its place
    hist = unescape(re.sub(r"<[^>]+>", " ", c.request("/history")[2].decode()))
    assert "Type 1 study" in hist and "25 of 25 of the study" in hist
    first = c.request(f"/results/{rec['releases'][0]}")[2].decode()
    assert "Type 1 study, 1 of 25" in first and f'href="/type1/{rec["uuid"]}"' in first
    report = c.request(f"/results/{rec['releases'][0]}/report.pdf", timeout=180)[2]
    assert "Type 1 study, 1 of 25" in "".join(pg.extract_text() for pg in PdfReader(io.BytesIO(report)).pages)
    # two parts measured after it: SPC charts them alone, beside the study's Cg and Cgk at its tolerance
    _measure_until(running, lambda app: len(app.store.list(limit=None, parts_only=True)) >= 2, presses)
    spc = c.request("/spc?recipe=ref")[2].decode()
    assert "2 parts of J" in spc and _text(spc, "spc-type1").startswith(f"Cg {cg:.2f}, Cgk {cgk:.2f} at this tolerance")
    assert ("spc-gauge-warning" in spc) == (cg < 1.33 or cgk < 1.33)


def test_an_abort_through_the_page_keeps_the_releases(tmp_path, appliance_factory):
    running = appliance_factory(_doc(tmp_path))
    app = running.app
    c, auth = _client(app)
    assert c.json("/api/type1/abort", method="POST", headers=auth)[0] == 409  # nothing to abort
    # the form chooses the recipe: one whose rig's calibration expired is selected, and the study refused with why
    assert c.request("/type1?recipe=nosuch")[0] == 400
    status, body = _start(c, auth, recipe="old")
    assert status == 409 and "calibration expired on 2021-01-14" in body["error"]
    assert app.parts.recipe.name == "old"
    assert _start(c, auth, recipe="ref")[0] == 200 and app.parts.recipe.name == "ref"
    status, body = _start(c, auth, recipe="old")  # a running study is not cut short by another recipe's start
    assert status == 409 and "a Type 1 study of ref runs (0 of 25)" in body["error"] and app.parts.recipe.name == "ref"
    _measure_until(running, _done(2))
    # Home names the study and its count, not a part's verdict: the study's releases are not parts
    home = c.request("/")[2].decode()
    assert "TYPE 1 STUDY" in home and _text(home, "study-count") == "3 of 25" and 'id="tile"' not in home
    assert c.json("/api/type1/abort", method="POST", headers=auth)[0] == 200
    assert "TYPE 1 STUDY" not in c.request("/")[2].decode()
    rec = c.json("/api/type1")[1]["latest"]
    assert rec["status"] == "aborted" and len(rec["releases"]) == 2 and rec["study"] is None
    assert {m.uuid for m in _ok(app.store)} == set(rec["releases"])
    page = c.request("/type1")[2].decode()
    assert "aborted" in _text(page, "t1-ended") and 'id="t1-start-button"' not in page  # not logged in: no form
    # the quality engineer's nav names the page; an operator may not start a study
    assert allowed("quality", "gauge") and allowed("admin", "gauge") and not allowed("operator", "gauge")
    # a production part set since: the form offers the last study's reference part, not it
    assert c.json("/api/part", data={"part_id": "P-77"}, method="POST", headers=auth)[0] == 202
    wait_until(lambda: c.json("/api/state")[1]["part_id"] == "P-77", 10, what="part P-77 set")
    assert c.request("/login", {"token": Path(app.web.token_file).read_text().strip(), "csrf": c.csrf(),
                                "next": "/type1"})[0] == 200
    page = c.request("/type1")[2].decode()
    assert '<a href="/type1">Type 1</a>' in page and 'id="t1-start-button"' in page
    # the form in the recipe's unit and decimals: T from the recipe, x_ref left to the engineer (no certificate)
    assert 'id="t1-tolerance" value="5000.0"' in page and 'id="t1-reference" value=""' in page
    assert 'name="part_id" value="CS-1"' in page  # the last study's reference part
    assert 'id="t1-form-recipe">ref<' in page and "(J; active)" in page
    chosen = c.request("/type1?recipe=old")[2].decode()
    assert 'id="t1-form-recipe">old<' in chosen and "selected when the study starts" in chosen


def test_a_study_started_and_aborted_in_the_browser(browser, tmp_path, appliance_factory):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    running = appliance_factory(_doc(tmp_path))
    app = running.app
    wait = WebDriverWait(browser, 30)
    browser.get(app.web.url + "type1")
    assert browser.find_elements(By.ID, "t1-login") and not browser.find_elements(By.LINK_TEXT, "Type 1")
    browser.find_element(By.ID, "token").send_keys(Path(app.web.token_file).read_text().strip())
    browser.find_element(By.ID, "login-button").click()
    wait.until(lambda d: d.find_elements(By.ID, "t1-form"))
    assert browser.find_element(By.LINK_TEXT, "Type 1").get_attribute("href").endswith("/type1")
    browser.find_element(By.ID, "t1-reference").send_keys("125000,0")  # a decimal comma, in g·cm²
    n = browser.find_element(By.ID, "t1-n")
    n.clear()
    n.send_keys("25")
    browser.find_element(By.ID, "t1-start-button").click()
    wait.until(lambda d: d.find_elements(By.ID, "t1-count"))
    assert browser.find_element(By.ID, "t1-count").text == "0 of 25"
    presses = 0
    while not app.call_soon(lambda: _done(1)(app)).result(10):  # a run the loaded rig aborts is measured again
        assert presses < 10
        presses += 1
        wait.until(lambda d: d.find_element(By.ID, "t1-count").text == "0 of 25")
        browser.find_element(By.ID, "measure").click()
        running.wait_done(presses)
    wait.until(lambda d: d.find_element(By.ID, "t1-count").text == "1 of 25")  # the page as the daemon has it
    browser.find_element(By.ID, "t1-abort").click()
    wait.until(lambda d: d.find_elements(By.ID, "t1-ended"))
    rec = app.store.gauge_studies("type1", limit=1)[0]
    assert rec["status"] == "aborted" and rec["reference"] == pytest.approx(J_REF, rel=1e-12)
    assert len(rec["releases"]) == 1 and rec["count"] == 25
    assert "aborted by the web page (token login)" in browser.find_element(By.ID, "t1-ended").text
    assert "aborted: aborted" not in browser.find_element(By.ID, "t1-ended").text  # said once
    # a phone, 390×844: the form, the stored studies and a study's page fit, nothing scrolls sideways
    browser.set_window_size(390, 844)
    for path in ("type1", f"type1/{rec['uuid']}"):
        browser.get(app.web.url + path)
        wait.until(lambda d: d.execute_script("return document.readyState") == "complete")
        assert browser.find_elements(By.ID, "t1-recent" if path == "type1" else "t1-result")
        assert browser.execute_script("return document.documentElement.scrollWidth <= window.innerWidth"), (
            path, browser.execute_script("return [document.documentElement.scrollWidth, window.innerWidth]"))
