"""A held-out browser review's findings on a FAULT, the roles, a recipe's unit and the unreachable bar, each held: a
trigger in FAULT refused at once in the words every door uses (what is wrong, whom to ask), never shown as a
measurement running; Home in FAULT says whom to ask (an operator) or what to do (the quality role), never READY or
"press Measure"; an operator cannot abort a quality engineer's Type 1 study; a recipe's nominal read in the display
unit chosen in the same form and shown back in it; a fault's words without an exception's class name; Measure busy
while a measurement runs; the bar opaque and the card saying so while the appliance is unreachable. HTTP first, then
the pages in headless Chromium at 390×844 and 1280×800."""

from __future__ import annotations

import io
import threading
import tomllib
from pathlib import Path

import pytest

from tests.service.conftest import appliance_doc, wait_until
from tests.service.publish.web.test_service_web import Client
from tests.service.publish.web.test_service_web_browser import _post, browser  # noqa: F401 (the fixture)

#: the reviewer's fault, as the sequencer now words it
FAULT = "identification failed: encoder: only 2.5 full swing(s) found; expected at least 3"
#: whom an operator is told to ask (the default ``[web] contact``)
ASK = "ask the quality engineer on shift to acknowledge it"


def _users(tmp_path: Path, monkeypatch) -> Path:
    from service.cli import main

    users = tmp_path / "users.toml"
    for name, role in (("op", "operator"), ("qe", "quality")):
        monkeypatch.setattr("sys.stdin", io.StringIO(f"pass-{name}-12345\n"))
        assert main(["user", "add", name, "--role", role, "--users-file", str(users), "--password-stdin",
                     "--state-dir", str(tmp_path)]) == 0
    return users


def _login(url: str, name: str) -> tuple[Client, str]:
    c = Client(url)
    status, _, page = c.request("/login", {"user": name, "token": f"pass-{name}-12345", "csrf": c.csrf()})
    assert status == 200 and f"{name} (" in page.decode()
    return c, page.decode().split('name="csrf-token" content="')[1].split('"')[0]


def _card(html: str) -> str:
    """Home's card of the part in hand (``#now``), as served."""
    return html.split('id="now"', 1)[1].split("</div>", 1)[0]


def test_a_fault_s_words_carry_no_exception_class_name():
    from firmware_host.errors import fault_words
    from measurement.errors import TraceError

    assert fault_words(TraceError("encoder: only 2.5 full swing(s) found")) == "encoder: only 2.5 full swing(s) found"
    assert "Error" not in fault_words(KeyError("x")) and fault_words(RuntimeError()).startswith("an error without")


def test_a_trigger_in_fault_is_refused_at_once_and_home_says_whom_to_ask(appliance_factory, tmp_path, monkeypatch):
    from service.core import vocabulary as V

    users = _users(tmp_path, monkeypatch)
    running = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True, "users_file": str(users)}))
    app = running.app
    op, ocsrf = _login(app.web.url, "op")
    qe, qcsrf = _login(app.web.url, "qe")
    app.sequencer.fault(FAULT)
    running.wait_event(lambda e: e.state.value == "FAULT", 10, what="FAULT")

    # Measure in FAULT: refused at once (not 202 and a "measurement requested"), saying what and whom to ask
    status, doc = op.json("/api/measure", method="POST", headers={"X-CSRF-Token": ocsrf})
    assert status == 409 and FAULT in doc["error"] and ASK in doc["error"], doc
    # another door (MQTT, Modbus) hears the same words from the daemon
    heard: list = []
    answered = threading.Event()
    def hear(r) -> None:
        heard.append(r)
        answered.set()
    app.command(V.TRIGGER, "mqtt", None, hear)
    assert answered.wait(10)
    assert (heard[0].status, heard[0].reason, heard[0].detail) == ("refused", "fault", doc["error"])
    assert app.store.count() == 0 and app.sequencer.state.value == "FAULT"

    # Home in FAULT, by role: never READY or "press Measure"; an operator told whom to ask, quality what to do
    for page in (op.request("/")[2].decode(), op.request("/home/summary")[2].decode()):
        card = _card(page)
        assert "FAULT" in card and "READY" not in card and "press Measure" not in card and "ask the quality" in card
    home = op.request("/")[2].decode()
    assert f'data-fault-words="fault: {ASK}"' in home and f">fault: {ASK}</span>" in home
    assert "once the cause is fixed</span>" not in home  # not an instruction the operator cannot follow
    qcard = _card(qe.request("/")[2].decode())
    assert "acknowledge the fault with Abort" in qcard and "READY" not in qcard
    assert "TraceError" not in home

    # a Type 1 study is aborted by the role that starts one
    status, doc = op.json("/api/type1/abort", method="POST", headers={"X-CSRF-Token": ocsrf})
    assert status == 403 and "may not start or abort a gauge study" in doc["error"], doc

    # acknowledged by the quality engineer: ready again
    assert qe.json("/api/abort", method="POST", headers={"X-CSRF-Token": qcsrf})[0] == 202
    running.wait_event(lambda e: e.state.value == "IDLE" and e.previous.value == "ABORTED", 10, what="acknowledged")
    wait_until(lambda: "READY" in _card(op.request("/")[2].decode()), 10, what="ready after the acknowledgement")


def _recipe_dir(tmp_path: Path) -> Path:
    d = tmp_path / "recipes"
    d.mkdir()
    for name, number in (("rotor-a", 3), ("rotor-b", 4)):
        (d / f"{name}.toml").write_text(f'[recipe]\nname = "{name}"\nnumber = {number}\nnominal = 0.0125\n'
                                        'tolerance_percent = 1.0\ndisplay_unit = "kg·m²"\n', encoding="utf-8")
    return d


def _file(d: Path, name: str) -> dict:
    return tomllib.loads((d / f"{name}.toml").read_text(encoding="utf-8"))["recipe"]


def test_a_recipe_s_nominal_is_read_in_the_unit_chosen_in_the_same_form(appliance_factory, tmp_path, monkeypatch):
    users = _users(tmp_path, monkeypatch)
    d = _recipe_dir(tmp_path)
    running = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True, "users_file": str(users)},
                                              recipes={"directory": str(d)}))
    qe, csrf = _login(running.app.web.url, "qe")
    # the reviewer's edit: g·cm² chosen, 125000 typed meaning g·cm²: 0.0125 kg·m², not 125000 kg·m²
    status, _, page = qe.request("/recipes", {"recipe": "rotor-a", "nominal": "125000", "display_unit": "g·cm²",
                                              "csrf": csrf})
    assert status == 200
    saved = _file(d, "rotor-a")
    assert saved["nominal"] == pytest.approx(0.0125, rel=1e-12) and saved["display_unit"] == "g·cm²"
    # shown back with a confirmation line in the chosen unit, the form's labels in it
    html = page.decode()
    said = html.split('id="recipe-saved"', 1)[1].split("</p>", 1)[0]
    assert "Saved rotor-a: nominal 125000" in said and "g·cm²" in said and "kg·m²" not in said, said
    assert "nominal (g·cm²)" in html.split('id="edit-3"', 1)[1].split("</form>", 1)[0]
    # the reviewer's number kept in kg·m²: no moment of inertia this torsion rig measures (k and the capture's
    # swings bound it), refused by the nominal's label and nothing written
    status, _, page = qe.request("/recipes", {"recipe": "rotor-b", "nominal": "125000", "csrf": csrf})
    html = page.decode()
    assert status == 400 and "beyond what this rig measures" in html and "is the number in kg·m²?" in html, html[-3000:]
    assert _file(d, "rotor-b")["nominal"] == 0.0125
    from service.publish.web.recipes import largest_inertia

    rig = running.app.config.rig
    assert largest_inertia(rig, 30.0, 3.0) == pytest.approx(rig.stiffness * (10.0 / (2 * 3.141592653589793)) ** 2
                                                            - (rig.tare_inertia or 0.0))
    # only the unit changed, the nominal left as the form showed it (kg·m²): its value kept, not read in g·cm²
    status, _, _ = qe.request("/recipes", {"recipe": "rotor-b", "nominal": "0.0125", "display_unit": "g·cm²",
                                           "csrf": csrf})
    assert status == 200
    assert _file(d, "rotor-b")["nominal"] == 0.0125 and _file(d, "rotor-b")["display_unit"] == "g·cm²"


@pytest.mark.browser
def test_the_fault_measure_busy_the_unreachable_bar_and_the_recipe_unit_in_the_browser(
        browser, appliance_factory, tmp_path, monkeypatch):  # noqa: F811
    from selenium.common.exceptions import StaleElementReferenceException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select, WebDriverWait

    from tests.service.publish.web.test_service_web_pages_live import _body, _Cable, _open

    users = _users(tmp_path, monkeypatch)
    d = _recipe_dir(tmp_path)
    doc = appliance_doc(tmp_path / "state", web={"enabled": True, "users_file": str(users)},
                        recipes={"directory": str(d), "active": "rotor-a"})
    doc["sequencer"]["capture_duration"] = 300.0  # a capture long enough to look at Measure during it
    running = appliance_factory(doc)
    app = running.app
    token = Path(app.web.token_file).read_text().strip()
    bearer = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    cable = _Cable(int(app.web.url.rstrip("/").rsplit(":", 1)[1]))
    url = cable.url.rstrip("/")
    wait = WebDriverWait(browser, 30, poll_frequency=0.05, ignored_exceptions=(StaleElementReferenceException,))

    def log_in(name: str) -> None:
        browser.delete_all_cookies()
        _open(browser, wait, url + "/")
        browser.find_element(By.ID, "user").send_keys(name)
        browser.find_element(By.ID, "token").send_keys(f"pass-{name}-12345")
        browser.find_element(By.ID, "login-button").click()
        wait.until(lambda dr: dr.find_elements(By.ID, "who"))

    try:
        for width, height in ((390, 844), (1280, 800)):
            browser.set_window_size(width, height)
            log_in("op")
            _open(browser, wait, url + "/")
            measure = browser.find_element(By.ID, "measure")
            # a measurement runs: Measure busy and disabled, not green
            _post(app.web.url + "api/measure", {}, bearer)
            wait.until(lambda dr: dr.find_element(By.ID, "state").text == "CAPTURING")
            wait.until(lambda dr: not dr.find_element(By.ID, "measure").is_enabled())
            assert measure.get_attribute("aria-busy") == "true"
            green = "rgb(23, 102, 58)"
            assert measure.value_of_css_property("background-color") != green
            _post(app.web.url + "api/abort", {}, bearer)
            wait.until(lambda dr: dr.find_element(By.ID, "state").text == "IDLE")
            wait.until(lambda dr: dr.find_element(By.ID, "measure").is_enabled())

            # FAULT pushed to the open page: the card says whom to ask, never READY; a press is refused at once
            app.sequencer.fault(FAULT)
            wait.until(lambda dr: "ask the quality" in dr.find_element(By.ID, "now").text)
            card = browser.find_element(By.ID, "now").text
            assert "READY" not in card and "press Measure" not in card, card
            assert browser.find_element(By.ID, "words").text == f"fault: {ASK}"
            assert measure.get_attribute("aria-disabled") == "true"
            measure.click()
            said = wait.until(lambda dr: dr.find_element(By.ID, "message").text)
            assert ASK in said and "FAULT" in said, said
            assert browser.find_element(By.ID, "now").get_attribute("data-measuring") is None
            assert "MEASURING" not in browser.find_element(By.ID, "now").text
            assert "TraceError" not in browser.find_element(By.TAG_NAME, "body").text
            _post(app.web.url + "api/abort", {}, bearer)  # acknowledged (the token acts as admin)
            wait.until(lambda dr: "READY" in dr.find_element(By.ID, "now").text)
            assert browser.find_element(By.ID, "state").text == "IDLE"

            # unreachable: the bar stays opaque (nothing shows through it), the card says why nothing is measured
            cable.pull()
            wait.until(lambda dr: _body(dr, "data-offline") == "1")
            bar = browser.find_element(By.ID, "actionbar")
            assert bar.value_of_css_property("opacity") == "1"
            assert bar.value_of_css_property("background-color") in ("rgb(255, 255, 255)", "rgba(255, 255, 255, 1)")
            card = browser.find_element(By.ID, "now").text
            assert "not reachable" in card and "press Measure" not in card and "READY" not in card, card
            cable.plug()
            wait.until(lambda dr: _body(dr, "data-offline") is None)
            wait.until(lambda dr: "READY" in dr.find_element(By.ID, "now").text)

        # the recipe form: the labels follow the unit chosen at once; a number left as shown converted with it
        log_in("qe")
        _open(browser, wait, url + "/recipes")
        browser.find_element(By.CSS_SELECTOR, "#recipe-4 details summary").click()
        form = browser.find_element(By.ID, "edit-4")
        label = form.find_element(By.CSS_SELECTOR, "label[for=edit-4-nominal]")
        assert label.text == "nominal (kg·m²)"
        Select(form.find_element(By.NAME, "display_unit")).select_by_visible_text("g·cm²")
        assert label.text == "nominal (g·cm²)"
        assert form.find_element(By.NAME, "nominal").get_attribute("value") == "125000"
        nominal = form.find_element(By.NAME, "nominal")
        nominal.clear()
        nominal.send_keys("126000")
        note = form.find_element(By.CSS_SELECTOR, ".recipe-unit-note").text
        assert "nominal 126000 g·cm² (= 0.0126 kg·m²)" in note and "kg·m² → g·cm²" in note, note
        form.find_element(By.CSS_SELECTOR, "button[type=submit]").click()
        said = wait.until(lambda dr: dr.find_element(By.ID, "recipe-saved")).text
        assert "nominal 126000" in said and "g·cm²" in said, said
        assert _file(d, "rotor-b")["nominal"] == pytest.approx(0.0126, rel=1e-12)
    finally:
        cable.pull()
