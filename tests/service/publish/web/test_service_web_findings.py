"""A browser review's findings, each held: the header's login legible (WCAG AA contrast computed from the page's own
colours), a finished tensor set acknowledged on Home, a rig without a calibration record said on Home and on the
result, the set-up page grouped with units and no path for a visitor, and the small ones (the SPC axis titles clear of
their ticks, the tensor drawing whole, every page's link in sight on a phone, "0.0 %" for a perfect part, the part ID
on a phone's history, no backticks, no Python list in a sentence). Unit checks of the page functions first, then the
pages in headless Chromium at 390×844 and 1280×800."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest

from tests.service.conftest import appliance_doc
from tests.service.publish.web.test_service_web_browser import _post, browser  # noqa: F401 (the fixture)
from tests.service.publish.web.wcag import contrast

SIZES = ((390, 844), (1280, 800))


# --- the page functions ---------------------------------------------------------------------------------------------

def test_a_deviation_that_rounds_to_nothing_has_no_sign():
    from service.publish.quality import judgement, percent

    assert percent(-0.04) == "0.0 %" and percent(0.049) == "0.0 %" and percent(-0.0) == "0.0 %"
    assert percent(-0.06) == "−0.1 %" and percent(1.25) == "+1.2 %"
    view = {"recipe": {"nominal": 0.0125, "lower": 0.01225, "upper": 0.01275}, "value": 0.0125 * (1 - 2e-6), "U": 0}
    said = judgement(view)
    assert said is not None and said["deviation"] == "0.0 %"


def test_a_rig_without_a_calibration_record_is_said_by_one_rule_and_not_blocked():
    import datetime as dt

    from measurement import Rig
    from measurement.rig import CalibrationRecord
    from service.parts.calibration import UNCALIBRATED, calibration_state, measure_block, uncalibrated

    bare = Rig(kind="torsion", stiffness=0.3651)
    assert uncalibrated(calibration_state(bare, [], 1.8e9)) == UNCALIBRATED
    assert UNCALIBRATED == "rig not calibrated: k from the rig file, no calibration record"
    assert measure_block(bare, None, [], 1.8e9, "the lab") is None  # said, not refused
    calibrated = Rig(kind="torsion", stiffness=0.3651, calibration=CalibrationRecord(dt.date(2026, 1, 15), 365))
    assert uncalibrated(calibration_state(calibrated, [], 1.78e9)) is None
    # a failed check standard on a rig without a record: blocked, and still said to be uncalibrated
    failed = [{"name": "ref", "E_n": 2.0, "passed": False, "finished_at": 1.7e9}]
    assert uncalibrated(calibration_state(bare, failed, 1.8e9)) == UNCALIBRATED
    # a set-up that requires a calibration record: the same rule refuses, in the same words, whom to call
    block = measure_block(bare, None, [], 1.8e9, "the lab", require_record=True)
    assert block is not None and block["uncalibrated"] and block["detail"] == (
        "rig not calibrated: k from the rig file, no calibration record: calibrate the rig (moi calibrate) or call "
        "the lab")
    assert measure_block(calibrated, None, [], 1.78e9, "the lab", require_record=True) is None


def test_a_set_up_that_requires_a_calibration_record_refuses_measure_at_the_page(appliance_factory, tmp_path):
    from tests.service.publish.web.test_service_web import Client

    running = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True},
                                              device={"require_calibration": True}))
    app = running.app
    token = Path(app.web.token_file).read_text().strip()
    status, doc = Client(app.web.url).json("/api/measure", method="POST",
                                           headers={"Authorization": f"Bearer {token}"})
    assert status == 409 and "Rig not calibrated: k from the rig file, no calibration record" in doc["error"], doc
    assert app.store.count() == 0 and not app.sequencer.busy
    home = Client(app.web.url).request("/")[2].decode()
    assert 'id="blocked"' in home and 'id="uncalibrated"' in home


def test_the_set_up_words_group_the_configuration_with_units_and_hide_paths_from_a_visitor(tmp_path):
    from service.config.appliance import SCHEMA, load_config
    from service.publish.web.set_up import mask, setup_words, unit_in_doc

    assert unit_in_doc("capture after the release (at most), s") == "s"
    assert unit_in_doc("release angle, rad") == "rad" and unit_in_doc("fewer samples → FAULT") is None
    assert unit_in_doc("sample rate of the direct sensor (at most: 500, 1500), Hz of simulated time") \
        == "Hz of simulated time"
    config = load_config(Path(__file__).resolve().parents[4] / "examples" / "appliance.toml")
    for logged_in in (False, True):
        groups = setup_words(mask(config.to_dict()), SCHEMA, shown_paths=logged_in)
        titles = [g[0] for g in groups]
        assert titles[:3] == ["Appliance", "Rig", "Recipes"] and "Sequencer" in titles and "MQTT" in titles
        rows = {(g, label): text for g, group, _open in groups for label, text in group}
        assert rows[("Sequencer", "capture duration")] == "30 s"
        assert rows[("Rig", "stiffness")] == "0.3651 N·m/rad" and rows[("Rig", "tare inertia")].endswith(" kg·m²")
        assert rows[("MQTT", "keepalive")] == "30 s" and rows[("Hardware", "solenoid › max on time")] == "0.5 s"
        assert rows[("Appliance", "not in use")] == "Simulated rig, OPC UA, Sparkplug B"
        assert rows[("Hardware", "encoder › direction")] == "1"  # a direction, not a directory
        paths = [rows[("Appliance", "configuration file")], rows[("Appliance", "rig file")],
                 rows[("MQTT", "password file")], rows[("Hardware", "encoder › port")]]
        if logged_in:
            assert paths[0].endswith("appliance.toml") and paths[3] == "/dev/ttyUSB0"
        else:
            assert set(paths) == {"(shown after logging in)"}
            assert not any(text.startswith(("/", "~", ".")) or ".toml" in text for text in rows.values()), rows


def test_a_chart_s_left_margin_holds_its_longest_tick_label_beside_the_axis_title():
    from service.publish.quality import TICK_CHAR, TITLE_BAND, _panel

    for width in (380.0, 720.0):
        values = [0.0125001234 + 1e-9 * i for i in range(20)]
        panel = _panel(values, [("centre", 0.01250124, "centre")], set(), width, 300.0, 2e-8)
        longest = max(len(text) for _y, text in panel["yticks"])
        assert longest >= 10  # the long labels that overlapped the title
        # the ticks end 4 px left of the axis; their start right of the title's band
        assert panel["left"] - 4 - TICK_CHAR * longest >= TITLE_BAND, (width, panel["left"], longest)


def test_the_tensor_drawing_keeps_its_label_and_its_frame_whole():
    from service.publish.web.drawing import LABEL_WIDTH, axes_drawing

    r = 0.5 ** 0.5
    for size in (150, 220):
        for axis, offset in (((1, 0, 0), (0.0, 0.03, -0.02)), ((0, 1, 0), None), ((0, 0, 1), None),
                             ((r, r, 0), None), ((r, 0, r), (0.01, 0.025, 0.0)), ((0, r, r), None)):
            d = axes_drawing(axis, offset, size=size)
            x, y, anchor = d["axis_label"]
            left, right = (x - LABEL_WIDTH, x) if anchor == "end" else (x, x + LABEL_WIDTH)
            assert left >= 0 and right <= size and 12 <= y <= size, (axis, size, d["axis_label"])
            for (ax, ay) in d["axis"]:
                assert 0 <= ax <= size and 0 <= ay <= size, (axis, size, d["axis"])
            ox, oy = d["origin"]
            lengths = {name: math.hypot(ex - ox, ey - oy) for name, (ex, ey) in d["frame"]}
            assert min(lengths.values()) >= 0.6 * max(lengths.values()), lengths  # x is no stub


def test_subgroups_of_unequal_size_are_said_without_a_python_list():
    from measurement.errors import InvalidInput
    from measurement.spc import xbar_s

    with pytest.raises(InvalidInput) as said:
        xbar_s([[1.0, 1.1], [1.0, 1.2, 1.1], [1.05, 1.0]])
    assert "got sizes 2, 3" in str(said.value) and "[" not in str(said.value)


# --- the pages in the browser ---------------------------------------------------------------------------------------

def _boxes_overlap(driver, svg) -> list[str]:
    """The tick labels of a chart that overlap its axis title (their boxes as the browser drew them)."""
    return driver.execute_script("""
        var t = arguments[0].querySelector('text.axis-label').getBoundingClientRect();
        return Array.from(arguments[0].querySelectorAll('text.tick')).filter(function (e) {
          var r = e.getBoundingClientRect();
          return r.left < t.right && t.left < r.right && r.top < t.bottom && t.top < r.bottom;
        }).map(function (e) { return e.textContent; });""", svg)


@pytest.mark.browser
def test_the_header_login_the_set_up_page_and_a_phone_s_navigation(browser, appliance_factory, tmp_path,  # noqa: F811
                                                                    monkeypatch):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    from service.cli import main

    users = tmp_path / "users.toml"
    monkeypatch.setattr("sys.stdin", io.StringIO("admin-password-1\n"))
    assert main(["user", "add", "ada", "--role", "admin", "--users-file", str(users), "--password-stdin",
                 "--state-dir", str(tmp_path)]) == 0
    running = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True, "users_file": str(users)}))
    url = running.app.web.url.rstrip("/")
    wait = WebDriverWait(browser, 30, poll_frequency=0.05)
    for width, height in SIZES:
        browser.set_window_size(width, height)
        browser.delete_all_cookies()
        browser.get(url + "/setup")
        # a wrong password: said in the header, legible there as its labels are
        wait.until(lambda d: d.find_element(By.ID, "user")).send_keys("ada")
        browser.find_element(By.ID, "token").send_keys("not-her-password")
        browser.find_element(By.ID, "login-button").click()
        error = wait.until(lambda d: d.find_element(By.ID, "login-error"))
        assert "wrong" in error.text
        for el in (browser.find_element(By.CSS_SELECTOR, "label[for=user]"),
                   browser.find_element(By.CSS_SELECTOR, "label[for=token]"), error):
            assert el.is_displayed() and contrast(browser, el) >= 4.5, (width, el.text, contrast(browser, el))
        # every page's link in sight, none pushed off the screen's edge
        inner = browser.execute_script("return window.innerWidth")
        links = browser.find_elements(By.CSS_SELECTOR, "header nav a")
        assert [a.text for a in links][-2:] == ["Tensor set", "Set-up"]
        for a in links:
            rect = browser.execute_script("var r = arguments[0].getBoundingClientRect(); return [r.left, r.right];", a)
            assert a.is_displayed() and rect[0] >= 0 and rect[1] <= inner, (width, a.text, rect, inner)
        # the set-up page to a visitor: grouped, each number with its unit, no file or folder of the appliance
        browser.get(url + "/setup")
        config = wait.until(lambda d: d.find_element(By.ID, "config"))
        text = config.get_attribute("textContent")
        groups = [h.get_attribute("textContent") for h in config.find_elements(By.CSS_SELECTOR, "summary h3")]
        assert groups[:3] == ["Appliance", "Rig", "Recipes"] and "Sequencer" in groups
        assert "capture duration8 s" in text.replace("\n", "") and "stiffness0.3651 N·m/rad" in text.replace("\n", "")
        # the health says the demo rig has no calibration record
        assert browser.find_element(By.ID, "health-calibration").text.startswith(
            "rig not calibrated: k from the rig file, no calibration record")
        body = browser.find_element(By.TAG_NAME, "body").get_attribute("textContent")
        assert "test.toml" not in body and str(tmp_path) not in body and "shown after logging in" in body
    # the admin logged in sees where the files are
    browser.find_element(By.ID, "user").send_keys("ada")
    browser.find_element(By.ID, "token").send_keys("admin-password-1")
    browser.find_element(By.ID, "login-button").click()
    wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, ".who .ok"))
    browser.get(url + "/setup")
    body = wait.until(lambda d: d.find_element(By.ID, "config")).get_attribute("textContent")
    assert "test.toml" in body and str(tmp_path / "state") in body


def _measure(url: str, bearer: dict, running, recipe: str, part: str) -> None:
    _post(url + "api/part", {"recipe": recipe, "part_id": part}, bearer)
    done = running.app.store.count()
    _post(url + "api/measure", {}, bearer)
    running.wait_done(done + 1, 90)


@pytest.mark.browser
def test_an_uncalibrated_rig_a_perfect_part_and_the_low_findings(browser, appliance_factory, tmp_path):  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    recipes = tmp_path / "recipes"
    recipes.mkdir()
    # the nominal the simulated part's J: a perfect part; kg·m² with many decimals: long tick labels on the chart
    (recipes / "exact.toml").write_text('[recipe]\nname = "rotor-exact"\nnumber = 7\nnominal = 0.0125\n'
                                        'tolerance_percent = 1.0\ndisplay_decimals = 8\n')
    running = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True},
                                              recipes={"directory": str(recipes), "active": "rotor-exact"}))
    app = running.app
    url = app.web.url
    token = Path(app.web.token_file).read_text().strip()
    bearer = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    for i in range(3):
        _measure(url, bearer, running, "rotor-exact", f"PLC-20{i}")
    last = app.store.latest()
    value = last.payload["part"]["value"]
    # the PDF's record says it in the same words
    from service.publish.report import report_lines
    facts = dict(report_lines(last, "kg·m²")[1])
    assert facts["calibration"] == "rig not calibrated: k from the rig file, no calibration record"
    wait = WebDriverWait(browser, 30, poll_frequency=0.05)
    for width, height in SIZES:
        browser.set_window_size(width, height)
        browser.get(url)
        # Home: the rig is said to be uncalibrated above the part in hand; measuring is not refused
        banner = wait.until(lambda d: d.find_element(By.ID, "uncalibrated"))
        assert "rig not calibrated: k from the rig file, no calibration record" in banner.text
        assert banner.is_displayed() and not browser.find_elements(By.ID, "blocked")
        assert browser.find_element(By.ID, "measure").get_attribute("aria-disabled") is None
        # the status line says what runs; what to do is said once, under the part (never "press Measure" over
        # "unload it")
        assert browser.find_element(By.ID, "words").text == "no measurement running"
        body = browser.find_element(By.TAG_NAME, "body").text
        assert "unload it" in body and "press Measure" not in body.split("unload it")[0]
        # a perfect part: no sign on a deviation that rounds to nothing
        why = browser.find_element(By.ID, "tile-why").text
        assert "−0.0 %" not in why and "+0.0 %" not in why
        if abs(100 * (value - 0.0125) / 0.0125) < 0.05:
            assert why.startswith("0.0 %"), why
        # the result says it too
        browser.get(f"{url}results/{last.uuid}")
        note = wait.until(lambda d: d.find_element(By.ID, "uncalibrated"))
        assert "rig not calibrated: k from the rig file, no calibration record" in note.text
        browser.get(f"{url}results/{last.uuid}/report")
        said = wait.until(lambda d: d.find_element(By.ID, "report-calibration")).text
        assert said == "rig not calibrated: k from the rig file, no calibration record", said
        # the history on a phone: the part ID in sight without scrolling sideways
        browser.get(url + "history")
        cell = wait.until(lambda d: d.find_element(By.CSS_SELECTOR, "#history td.part-id"))
        right = browser.execute_script("return arguments[0].getBoundingClientRect().right", cell)
        assert cell.text == "PLC-202" and right <= browser.execute_script("return window.innerWidth")
        # SPC and calibration: no literal backticks; the chart's axis titles clear of their tick labels
        for page in ("spc?recipe=rotor-exact", "calibration"):
            browser.get(url + page)
            wait.until(lambda d: d.execute_script("return document.readyState") == "complete")
            assert "`" not in browser.find_element(By.TAG_NAME, "body").text, page
        browser.get(url + "spc?recipe=rotor-exact")
        charts = [c for c in browser.find_elements(By.CSS_SELECTOR, "svg.chart") if c.is_displayed()]
        assert charts
        for chart in charts:
            ticks = [t.text for t in chart.find_elements(By.CSS_SELECTOR, "text.tick")]
            assert max(len(t) for t in ticks) >= 9, ticks
            assert _boxes_overlap(browser, chart) == [], (width, chart.get_attribute("id"))


@pytest.mark.browser
def test_a_finished_tensor_set_is_acknowledged_on_home(browser, appliance_factory, tmp_path):  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    from measurement.simulate import BRACKET
    from tests.service.parts.test_service_tensor_set import progress, tensor_doc

    doc = tensor_doc(tmp_path, web={"enabled": True})
    (tmp_path / "recipes" / "plc.toml").write_text('[recipe]\nname = "rotor-plc"\nnumber = 9\nnominal = 0.0125\n'
                                                   'tolerance_percent = 2.0\n')
    running = appliance_factory(doc)
    app = running.app
    url = app.web.url
    token = Path(app.web.token_file).read_text().strip()
    bearer = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    _measure(url, bearer, running, "rotor-plc", "PLC-2010")  # another recipe's part, measured before the set
    _post(url + "api/part", {"recipe": "bracket-tensor", "part_id": "BR-7"}, bearer)
    wait = WebDriverWait(browser, 30, poll_frequency=0.05)
    cfg = app.config
    for step in range(6):
        p = progress(running)
        assert p["status"] == "running" and p["part_id"] == "BR-7", p
        if step == 0:  # the drawing of the orientation to mount: its label inside, its x axis no stub
            for width, height in SIZES:
                browser.set_window_size(width, height)
                for page in ("", "set"):
                    browser.get(url + page)
                    svg = wait.until(lambda d: d.find_element(By.ID, "set-drawing"))
                    inside = browser.execute_script("""
                        var s = arguments[0].getBoundingClientRect();
                        return Array.from(arguments[0].querySelectorAll('text')).every(function (t) {
                          var r = t.getBoundingClientRect();
                          return r.left >= s.left - 0.5 && r.right <= s.right + 0.5 && r.top >= s.top - 0.5
                                 && r.bottom <= s.bottom + 0.5; });""", svg)
                    assert inside, (width, page)
                    lengths = browser.execute_script("""
                        return Array.from(arguments[0].querySelectorAll('line[marker-end]')).map(function (l) {
                          return Math.hypot(l.x2.baseVal.value - l.x1.baseVal.value,
                                            l.y2.baseVal.value - l.y1.baseVal.value); });""", svg)
                    assert len(lengths) == 3 and min(lengths) >= 0.6 * max(lengths), lengths
        o = p["orientation"]
        app.devices.sim.mount(BRACKET.mounted(cfg.rig, np.array(o["axis"]), o.get("offset"), cfg.simulation.effects))
        done = app.store.count()
        running.press()
        running.wait_done(done + 1, 90)
    sets = app.store.tensor_sets(1)
    assert sets and sets[0]["status"] == "complete" and sets[0]["part_id"] == "BR-7"
    for width, height in SIZES:
        browser.set_window_size(width, height)
        browser.get(url)
        now = wait.until(lambda d: d.find_element(By.ID, "now-box"))
        # the set's part and how it ended, linked to its page; not the older part of another recipe
        assert browser.find_element(By.ID, "tile-verdict").text == "COMPLETE"
        assert browser.find_element(By.ID, "tile-part").text == "BR-7"
        assert "tensor set bracket-tensor" in now.text and "PLC-2010" not in now.text
        assert browser.find_element(By.ID, "tile").get_attribute("href").endswith("/set")
        assert "unload it" in browser.find_element(By.ID, "next-step").text
