"""The web page in a real browser: headless Debian Chromium driven by Selenium, against the daemon on the
simulated rig. One browser session for the module. One scenario: refused without the token, log in, Measure,
the live states and the fit drawn over the swing, the result from the history with its plot; then parts that
are OK, NOK and INVALID, and every page (home, result, history, SPC, report) at a phone's width (390 px) and a
desktop's (1280 px): none wider than the window, the verdict's word on it, a screenshot of each kept as a test
artifact (in $MOI_ARTIFACTS when set, else in the test's temporary folder)."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
from pathlib import Path

import pytest

from tests.components import missing
from tests.service.conftest import appliance_doc, wait_until
from tests.service.publish.web.test_service_web import E_NOTATION, ISO_TIME, UUID
from tests.service.publish.web.wcag import contrast

pytestmark = pytest.mark.browser

REPO = Path(__file__).resolve().parents[4]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver") or ("/usr/bin/chromedriver" if os.path.exists("/usr/bin/chromedriver") else None)


@pytest.fixture(scope="module")
def browser():
    try:
        from selenium import webdriver
    except ImportError:
        missing("selenium is not installed (pip install -e '.[test]')")
    if CHROMIUM is None or CHROMEDRIVER is None:
        missing("headless Chromium is not installed: `make test` installs Debian's chromium and chromium-driver "
                    "when run as root; otherwise apt-get install chromium chromium-driver")
    from selenium.webdriver.chrome.service import Service

    os.environ.setdefault("SE_OFFLINE", "true")  # Selenium Manager must never try to download a driver
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--window-size=1100,1900", "--no-first-run", "--disable-extensions"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(options=opts, service=Service(CHROMEDRIVER))
    driver.set_page_load_timeout(30)
    driver.set_window_size(1280, 1900)
    yield driver
    driver.quit()


def test_measure_from_the_browser(browser, appliance_factory, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    # slow enough that the page sees every state: about 1 s of capture
    recipes = tmp_path / "recipes"
    recipes.mkdir()
    (recipes / "rotor.toml").write_text('[recipe]\nname = "rotor-12"\nnumber = 12\nnominal = 0.0125\n'
                                        'tolerance_percent = 1.0\n')
    (recipes / "nok.toml").write_text('[recipe]\nname = "rotor-nok"\nnumber = 13\nnominal = 0.015\n'
                                      'tolerance_percent = 1.0\ndisplay_unit = "kg*mm^2"\n')
    (recipes / "bad.toml").write_text('[recipe]\nname = "rotor-bad"\nnumber = 14\nnominal = 0.0125\nreleases = 2\n'
                                      'tolerance_percent = 1.0\n[quality]\nmax_J_std = 1.0e-15\n')
    # the recipe's rig calibrated twice, the newer one expired on 2021-01-14: its history on the Calibration page
    (tmp_path / "cal-rig.toml").write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n')
    from service.cli import main
    shutil.copy(REPO / "examples" / "calibration.toml", tmp_path / "calibration.toml")
    with contextlib.chdir(tmp_path):  # the files named as a user names them, relative
        for date, by in (("2019-01-15", "A. Meyer"), ("2020-01-15", "B. Kraus")):
            assert main(["calibrate", "calibration.toml", "--rig", "cal-rig.toml", "--out", "cal-rig.toml",
                         "--date", date, "--valid-days", "365", "--by", by]) == 0
    (recipes / "cal.toml").write_text('[recipe]\nname = "rotor-cal"\nnumber = 15\nnominal = 0.0125\n'
                                      'tolerance_percent = 1.0\nrig = "../cal-rig.toml"\n')
    doc = appliance_doc(tmp_path / "state", time_scale=5.0, web={"enabled": True, "contact": "the lab, ext. 2345"},
                        recipes={"directory": str(recipes), "active": "rotor-12"},
                        simulation={"effects": {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 6e-4}}})
    running = appliance_factory(doc)
    app = running.app
    url = app.web.url
    token = Path(app.web.token_file).read_text().strip()
    wait = WebDriverWait(browser, 30, poll_frequency=0.05)

    browser.get(url)
    wait.until(lambda d: d.find_element(By.ID, "state").text == "IDLE")
    # the script knows the states from the table served with the page, not from a copy of its own
    from service.states import vocabulary
    assert browser.execute_script("return moi.states") == vocabulary()

    # an action without the token is refused, and nothing moves
    browser.find_element(By.ID, "measure").click()
    wait.until(lambda d: "log in first" in d.find_element(By.ID, "message").text)
    assert app.sequencer.state.value == "IDLE" and app.store.count() == 0

    # a wrong token: said beside the field (not a bare 401 page), the form still there
    browser.find_element(By.ID, "token").send_keys("not-the-token")
    browser.find_element(By.ID, "login-button").click()
    wait.until(lambda d: "wrong token" in d.find_element(By.ID, "login-error").text)
    assert browser.find_element(By.CSS_SELECTOR, "label[for=token]").text == "token"
    # log in with the token; back on the home page, logged in
    browser.find_element(By.ID, "token").send_keys(token)
    browser.find_element(By.ID, "login-button").click()
    wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, ".who .ok"))

    # the live stream is connected (its first tick arrived): no transition can be missed from here on
    wait.until(lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-live") == "1")
    assert browser.find_element(By.ID, "state").text == "IDLE"
    assert browser.find_element(By.ID, "recipe").text == "12 rotor-12"

    # the part's serial number, set on the page, shows on it as the appliance's
    browser.find_element(By.ID, "part-id-input").send_keys("SN-0042")
    browser.find_element(By.CSS_SELECTOR, "#part-form button").click()
    wait.until(lambda d: d.find_element(By.ID, "part-id").text == "SN-0042")

    browser.find_element(By.ID, "measure").click()
    wait.until(lambda d: d.find_elements(By.ID, "latest-link") and "IDLE" in
               [li.get_attribute("data-state") for li in d.find_elements(By.CSS_SELECTOR, "#log li")][1:])
    seen = [li.get_attribute("data-state") for li in browser.find_elements(By.CSS_SELECTOR, "#log li")]
    assert seen[:6] == ["ARMED", "RELEASING", "CAPTURING", "IDENTIFYING", "PUBLISHING", "IDLE"], seen
    # the swing was drawn while it arrived, then the fit over it and the residual below
    assert browser.execute_script("return document.getElementById('swing').toDataURL().length") > 5000
    wait.until(lambda d: d.find_element(By.ID, "swing").get_attribute("data-fit") == "1")
    # the verdict tile came with the result, without a reload
    wait.until(lambda d: d.find_element(By.ID, "tile-verdict").text == "OK")
    assert browser.find_element(By.ID, "count-OK").text == "1"

    # the result, opened from the history
    browser.find_element(By.LINK_TEXT, "History").click()
    rows = wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#history td a"))
    rows[0].click()
    text = wait.until(lambda d: d.find_element(By.ID, "J")).text
    said = re.match(r"J = ([0-9.e+-]+) kg·m² ± ([0-9.e+-]+) kg·m² \(U, k = 2\)", text)
    assert said is not None, text
    J, U = (float(x) for x in said.groups())
    assert browser.find_element(By.ID, "verdict").text.split() == ["OK", "part", "OK"]
    assert browser.find_element(By.ID, "part-id").text == "SN-0042"
    truth = app.devices.sim.inertia
    assert abs(J - truth) <= max(2.5 * U, 1e-4 * truth), (J, U, truth)
    steps = [st for st in app.store.latest().payload["steps"] if st["chosen"]]
    shown = [li.text for li in browser.find_elements(By.CSS_SELECTOR, ".steps li")]
    assert [t.split(" ")[0] for t in shown] == [st["chosen"] for st in steps], (steps, shown)
    from service.publish.quality import plain_text  # (their numbers written out, without exponents)
    assert all(plain_text(st["reason"]) in t and plain_text(st["evidence"]) in t for st, t in zip(steps, shown)), (steps, shown)
    wait.until(lambda d: d.execute_script(
        "var i = document.getElementById('plot'); return i.complete && i.naturalWidth > 400;"))
    shot = tmp_path / "result-page.png"
    browser.save_screenshot(str(shot))
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 20_000
    if os.environ.get("MOI_UPDATE_SCREENSHOT"):  # refresh the picture in the README
        shutil.copy(shot, REPO / "docs" / "img" / "web-result.png")
    assert app.store.count() == 1
    ok = app.store.latest()

    # a NOK part and an INVALID one (two releases, both invalid), started over the API
    bearer = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    for recipe, part, n in (("rotor-nok", "SN-0041", 1), ("rotor-nok", "SN-0042", 1), ("rotor-nok", "SN-0043", 1),
                            ("rotor-bad", "SN-0044", 2)):
        _post(url + "api/part", {"recipe": recipe, "part_id": part}, bearer)
        for _ in range(n):
            done = app.store.count()
            _post(url + "api/measure", {}, bearer)
            running.wait_done(done + 1, 60)
    nok, bad = app.store.list(parts_only=True, limit=2, full=True)[::-1][-2:]
    assert (nok.part_verdict, bad.part_verdict) == ("NOK", "INVALID")

    # every result's plot is drawn (in the page's child process, at a lower priority: slow on a busy machine)
    # before the pages that show it are opened within the browser's page-load time
    for m in app.store.list(limit=None):
        wait_until(lambda: app.store.get_attachment(m.uuid, "plot.png") is not None, 300, 0.2, f"plot {m.seq}")

    artifacts = Path(os.environ.get("MOI_ARTIFACTS") or tmp_path / "screens")
    artifacts.mkdir(parents=True, exist_ok=True)
    pages = {"home": ("/", None), "result-ok": (f"/results/{ok.uuid}", "OK"),
             "result-nok": (f"/results/{nok.uuid}", "NOK"), "result-invalid": (f"/results/{bad.uuid}", "INVALID"),
             "history": ("/history", None), "spc": ("/spc?recipe=rotor-nok", None),
             "report": (f"/results/{bad.uuid}/report", "INVALID"), "recipes": ("/recipes", None),
             "calibration": ("/calibration", None), "setup": ("/setup", None)}
    for width in (390, 1280):
        browser.set_window_size(width, 900)
        for name, (path, verdict) in pages.items():
            browser.get(url.rstrip("/") + path)
            wait.until(lambda d: d.execute_script("return document.readyState") == "complete")
            _check_page(browser, name, width, verdict, artifacts)

    # the narrowest phone the layout is made for: still nothing wider than the window
    browser.set_window_size(360, 900)
    for path in ("/", f"/results/{bad.uuid}"):
        browser.get(url.rstrip("/") + path)
        wait.until(lambda d: d.execute_script("return document.readyState") == "complete")
        assert browser.execute_script("return document.documentElement.scrollWidth <= window.innerWidth"), path

    # the operator's phone, 390×844: the part in hand and Measure on one screen, without scrolling
    browser.set_window_size(390, 844)
    browser.get(url)
    wait.until(lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-live") == "1")
    height = browser.execute_script("return window.innerHeight")

    def on_screen(el) -> bool:
        r = browser.execute_script("var r = arguments[0].getBoundingClientRect(); return [r.top, r.bottom, r.left,"
                                   " r.right];", el)
        return el.is_displayed() and r[0] >= 0 and r[1] <= height and r[2] >= 0 and r[3] <= 390

    measure = browser.find_element(By.ID, "measure")
    tile = browser.find_element(By.ID, "tile")
    # verdict and Measure both inside the 390×844 viewport, the verdict not under the action bar
    assert browser.execute_script("return window.scrollY") == 0
    assert on_screen(tile) and on_screen(measure) and tile.rect["y"] + tile.rect["height"] <= measure.rect["y"]
    assert browser.find_element(By.ID, "tile-verdict").text == "INVALID"
    assert "SN-0044" in browser.find_element(By.ID, "tile-part").text
    assert browser.find_element(By.ID, "now").get_attribute("aria-live") == "polite"  # announced when it changes
    # Measure within three tab stops (the skip link first), and legible: WCAG AA contrast of Measure and IDLE
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys
    stops = []
    for _ in range(3):
        ActionChains(browser).send_keys(Keys.TAB).perform()
        stops.append(browser.execute_script("return document.activeElement.id || document.activeElement.tagName"))
        if stops[-1] == "measure":
            break
    assert stops[-1] == "measure", stops
    for el in (measure, browser.find_element(By.ID, "state")):
        assert contrast(browser, el) >= 4.5, (el.get_attribute("id"), contrast(browser, el))

    # the part is complete and its ID still set: Measure asks before measuring it again as a new part
    done = app.store.count()
    measure.click()
    alert = wait.until(lambda d: d.switch_to.alert)
    assert "SN-0044 is complete" in alert.text
    alert.dismiss()
    wait.until(lambda d: "not measured" in d.find_element(By.ID, "message").text)
    assert app.store.count() == done and not app.sequencer.busy
    measure.click()
    wait.until(lambda d: d.switch_to.alert).accept()
    # at once a neutral "measuring" for the part in hand: the last verdict is gone while the next part swings
    line = wait.until(lambda d: d.find_element(By.ID, "now-line"))
    assert line.text.startswith("MEASURING SN-0044 · release 1 of 2"), line.text
    assert not browser.find_elements(By.ID, "tile-verdict") and on_screen(line)
    wait.until(lambda d: d.find_element(By.ID, "swing").get_attribute("data-fit") == "1")
    assert app.store.count() == done + 1
    swing = browser.find_element(By.ID, "swing")
    assert swing.size["height"] >= 200 and int(swing.get_attribute("data-drawn")) > 100
    assert browser.execute_script("return document.documentElement.scrollWidth") <= 390
    # the same part ID again starts a new part: its first release is in, the second is next
    wait.until(lambda d: d.find_element(By.ID, "release-k").text == "next: release 2 of 2")
    wait.until(lambda d: d.find_element(By.ID, "now-line").text.startswith("IN PROGRESS SN-0044"))
    browser.save_screenshot(str(artifacts / "operator-390.png"))

    # Abort during the capture: the page says "aborted" (and does not drop silently to IDLE)
    browser.find_element(By.ID, "measure").click()
    wait.until(lambda d: d.find_element(By.ID, "state").text == "CAPTURING")
    browser.find_element(By.ID, "abort").click()
    wait.until(lambda d: "aborted" in d.find_element(By.ID, "message").text)
    wait.until(lambda d: d.find_element(By.ID, "state").text == "IDLE")
    assert "aborted" in browser.find_element(By.ID, "message").text
    assert app.store.latest(None).status == "aborted"

    # an expired calibration: a banner that says what to do and whom to call, and Measure refused
    bearer = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    _post(url + "api/part", {"recipe": "rotor-cal", "part_id": "SN-0045"}, bearer)
    wait_until(lambda: app.parts.recipe.name == "rotor-cal", 10, what="rotor-cal selected")
    browser.get(url)
    banner = wait.until(lambda d: d.find_element(By.ID, "blocked"))
    assert on_screen(banner) and "expired on 2021-01-14" in banner.text and "the lab, ext. 2345" in banner.text
    # the part left at release 1 of 2 (SN-0044, another recipe) is not this part's progress: this one is ready
    assert browser.find_element(By.ID, "now-line").text.startswith("READY SN-0045 · release 1 of 1")
    assert "SN-0044" in browser.find_element(By.ID, "left-part").text
    done = app.store.count()
    browser.find_element(By.ID, "measure").click()
    wait.until(lambda d: "Measure refused" in d.find_element(By.ID, "message").text)
    assert app.store.count() == done and not app.sequencer.busy
    browser.save_screenshot(str(artifacts / "blocked-390.png"))
    if os.environ.get("MOI_UPDATE_SCREENSHOT"):
        for name in ("operator-390", "blocked-390", "recipes-1280", "calibration-1280", "setup-1280", "spc-1280",
                     "spc-390"):
            shutil.copy(artifacts / f"{name}.png", REPO / "docs" / "img" / f"web-{name}.png")


def _check_page(browser, name: str, width: int, verdict: str | None, artifacts: Path) -> None:
    """One page at one window width: nothing wider than the window, no e-notation nor machine time, one main
    heading, the verdict where the page has one, what the page itself must show; then its screenshot."""
    from selenium.webdriver.common.by import By

    inner = browser.execute_script("return window.innerWidth")
    wide = browser.execute_script("return document.documentElement.scrollWidth")
    offenders = browser.execute_script(
        "return Array.from(document.querySelectorAll('body *')).filter(e => e.getBoundingClientRect().right"
        " > window.innerWidth + 1).slice(0, 5).map(e => e.tagName + '.' + e.className + '#' + e.id)")
    # nothing wider than the window: tables scroll inside their card
    assert wide <= inner, (name, width, wide, inner, offenders)
    # a person reads no number in e-notation and no machine time on the operator's and quality pages
    shown = UUID.sub("", browser.find_element(By.TAG_NAME, "body").text)
    found = E_NOTATION.search(shown) or ISO_TIME.search(shown)
    assert found is None, (name, width, found and shown[max(0, found.start() - 80):found.end() + 40])
    assert len(browser.find_elements(By.TAG_NAME, "h1")) == 1  # one main heading on every page
    if verdict is not None:
        head = browser.find_element(By.ID, "verdict")
        assert head.text.split()[0] == verdict and head.is_displayed()
        assert head.rect["x"] >= 0 and head.rect["x"] + head.rect["width"] <= inner
    if name == "home":
        swing = browser.find_element(By.ID, "swing")
        assert swing.size["height"] >= 200 and swing.size["width"] <= inner  # readable on a phone
        assert browser.find_element(By.ID, "tile-verdict").text == "INVALID"
    if name == "spc":  # the chart in the recipe's unit; on a phone its own drawing, labels readable
        chart = browser.find_element(By.ID, "chart-points" if width > 600 else "chart-points-narrow")
        assert chart.is_displayed() and "kg·mm²" in chart.text and "UCL" in chart.text
        assert chart.rect["x"] >= 0 and chart.rect["x"] + chart.rect["width"] <= inner
        tick = chart.find_element(By.CSS_SELECTOR, "text.tick")
        assert tick.rect["height"] >= 9, tick.rect  # px: not the 7 px text of a shrunken desktop chart
        clipped = browser.execute_script(
            "var r = arguments[0].getBoundingClientRect(); return Array.from(arguments[0].querySelectorAll("
            "'text')).filter(t => t.getBoundingClientRect().right > r.right + 0.5).map(t => t.textContent)", chart)
        assert not clipped, clipped  # every label whole
        assert "95 % confidence" in browser.find_element(By.ID, "capability").text
    if name == "report" and width == 1280:  # it prints cleanly: the record, not the page's navigation
        import base64
        import io

        from pypdf import PdfReader
        printed = PdfReader(io.BytesIO(base64.b64decode(browser.print_page())))
        text = " ".join(pg.extract_text() for pg in printed.pages)
        assert "part INVALID" in text and "SN-0044" in text and "Tensor set" not in text
        # the record and its budget (the correlated pair's own lines under its row): four A4 pages at most
        assert len(printed.pages) <= 4
    if name == "calibration":  # the recipe rig's two calibrations, newest first, within the window
        rows = browser.find_elements(By.CSS_SELECTOR, "tr.cal-row")
        assert [r.text.split()[0] for r in rows] == ["2020-01-15", "2019-01-15"] and "B. Kraus" in rows[0].text
        if width == 1280:  # the whole row on a desktop: no sideways scrolling to who and when
            box = browser.find_element(By.CSS_SELECTOR, "table.cal-history").find_element(By.XPATH, "..")
            assert browser.execute_script("return arguments[0].scrollWidth <= arguments[0].clientWidth", box)
    if name == "history":
        table = browser.find_element(By.ID, "history")
        assert "part verdict" in table.text and "NOK" in table.text
        if width == 1280:  # the whole row on a desktop: no sideways scrolling to the status and flags
            box = table.find_element(By.XPATH, "..")
            assert browser.execute_script("return arguments[0].scrollWidth <= arguments[0].clientWidth", box)
    # the whole page in one picture
    height = browser.execute_script("return document.documentElement.scrollHeight")
    browser.set_window_size(width, min(max(height + 120, 600), 6000))
    shot = artifacts / f"{name}-{width}.png"
    browser.save_screenshot(str(shot))
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    browser.set_window_size(width, 900)


def _post(url: str, data: dict, headers: dict) -> None:
    import json
    import urllib.parse
    import urllib.request

    req = urllib.request.Request(url, data=urllib.parse.urlencode(data).encode(), headers=headers, method="POST")
    with urllib.request.urlopen(req, timeout=30) as r:
        assert r.status == 202, json.loads(r.read())
