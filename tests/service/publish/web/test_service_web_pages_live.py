"""Every page, not only Home, kept open in headless Chromium at a phone's 390×844 and a desktop's 1280×800 while
the appliance changes under it: a calibration block pushed to the open page (the banner, Measure refused without
a press), the appliance unreachable (the page greys, its buttons disabled, "not reachable since …") and back, and
the daemon restarted under the page (it says the part in hand and the login were lost, and is served again by the
new daemon). Then the review's figures as a browser shows them: every number of a part in its unit and decimals
(its NOK and INVALID reasons included), the uncertainty budget's units and shares, the DFQ's local times, a long
scan refused with its length, and concurrent edits of users and of recipes refused and audited.

The appliance is made unreachable without stopping it by a relay on 127.0.0.1 between the browser and the page
(``_Cable``): pulled, every connection through it is closed and new ones are refused; plugged in again, the same
daemon answers."""

from __future__ import annotations

import contextlib
import re
import socket
import threading
import urllib.request
from pathlib import Path

import pytest

from tests.service.conftest import appliance_doc
from tests.service.publish.web.test_service_web import Client, _three_release_doc
from tests.service.publish.web.test_service_web_browser import _post, browser  # noqa: F401 (the fixture)

pytestmark = pytest.mark.browser

#: the pages walked besides Home: a page of stored results, the calibration's, and a page with forms
PAGES = ("/history", "/calibration", "/recipes")
#: what every page says when the appliance does not answer
UNREACHABLE = re.compile(r"appliance not reachable since \d\d:\d\d:\d\d")


class _Cable:
    """A TCP relay on 127.0.0.1 from the browser to the appliance's web port (``target``), which the test pulls
    out (every connection through it closed, new ones refused) and plugs in again on the same port."""

    def __init__(self, target: int) -> None:
        self.target = target
        self.port = 0
        self._lock = threading.Lock()
        self._open: set[socket.socket] = set()
        self._listener: socket.socket | None = None
        self.plug()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    def plug(self) -> None:
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", self.port))
        s.listen(64)
        self.port = s.getsockname()[1]
        self._listener = s
        threading.Thread(target=self._accept, args=(s,), name="test-cable", daemon=True).start()

    def pull(self) -> None:
        s, self._listener = self._listener, None
        if s is not None:
            _close(s)
        with self._lock:
            cut, self._open = self._open, set()
        for c in cut:
            _close(c)

    def _accept(self, listener: socket.socket) -> None:
        while True:
            try:
                near, _ = listener.accept()
            except OSError:  # pulled
                return
            try:
                far = socket.create_connection(("127.0.0.1", self.target), timeout=10)
            except OSError:  # the appliance is down: the browser's connection is closed as a refusal would be
                _close(near)
                continue
            far.settimeout(None)
            with self._lock:
                self._open |= {near, far}
            for a, b in ((near, far), (far, near)):
                threading.Thread(target=self._pipe, args=(a, b), name="test-cable-pipe", daemon=True).start()

    def _pipe(self, a: socket.socket, b: socket.socket) -> None:
        try:
            while data := a.recv(65536):
                b.sendall(data)
        except OSError:
            pass
        finally:
            for s in (a, b):
                _close(s)
            with self._lock:
                self._open -= {a, b}


def _close(s: socket.socket) -> None:
    with contextlib.suppress(OSError):
        s.shutdown(socket.SHUT_RDWR)  # wakes a thread blocked in accept() or recv() on it
    s.close()


def _boot(appliance_url: str) -> str:
    import json

    with urllib.request.urlopen(appliance_url + "api/state", timeout=30) as r:
        return json.loads(r.read())["boot"]


def _body(driver, attribute: str) -> str | None:
    return driver.execute_script(f"return document.body.getAttribute('{attribute}')")


def _buttons(driver) -> list[tuple[str, bool]]:
    """Every button of the page (its words, whether it can be pressed), hidden ones included."""
    return [tuple(b) for b in driver.execute_script(
        "return Array.from(document.querySelectorAll('button, input[type=submit]')).map("
        "b => [(b.textContent || b.value).trim(), !b.disabled])")]


def _all_grey(driver) -> bool:
    """Whether everything the page shows under its header but the words of the outage is greyed."""
    return driver.execute_script(
        "var shown = Array.from(document.querySelector('main').children).filter("
        " e => e.id !== 'offline' && e.id !== 'restarted' && e.getClientRects().length);"
        " return shown.length > 0 && shown.every(e => getComputedStyle(e).filter.indexOf('grayscale') >= 0);")


def _log_in(driver, wait, token: str) -> None:
    from selenium.webdriver.common.by import By

    driver.find_element(By.ID, "token").send_keys(token)
    driver.find_element(By.ID, "login-button").click()
    wait.until(lambda d: d.find_elements(By.ID, "who"))


def _open(driver, wait, url: str) -> None:
    """``url`` open and its live stream connected (its first tick arrived)."""
    driver.get(url)
    wait.until(lambda d: _body(d, "data-live") == "1")


@pytest.fixture
def rig(appliance_factory, tmp_path):
    """The simulated rig with the shared recipes and a three-release part type, reached through a cable."""
    doc = _three_release_doc(tmp_path)
    running = appliance_factory(doc)
    cable = _Cable(int(running.app.web.url.rstrip("/").rsplit(":", 1)[1]))
    yield doc, running, cable
    cable.pull()


@pytest.mark.parametrize("size", [(390, 844), (1280, 800)], ids=("phone", "desktop"))
def test_every_open_page_follows_a_block_an_outage_and_a_restart(browser, appliance_factory, rig,  # noqa: F811
                                                                 size):
    from selenium.common.exceptions import StaleElementReferenceException, WebDriverException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    doc, running, cable = rig
    token = Path(running.app.web.token_file).read_text().strip()
    wait = WebDriverWait(browser, 60, poll_frequency=0.05, ignored_exceptions=(StaleElementReferenceException,))
    browser.set_window_size(*size)
    _open(browser, wait, cable.url)
    _log_in(browser, wait, token)

    # a calibration block pushed to the open page: the banner at once, Home's Measure refused without a press
    direct = running.app.web.url
    bearer = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    for path in ("/", *PAGES[:2]):
        _open(browser, wait, cable.url.rstrip("/") + path)
        assert not browser.find_elements(By.ID, "blocked"), path
        _post(direct + "api/part", {"recipe": "rotor-cal"}, bearer)  # the PLC selects it, elsewhere
        banner = wait.until(lambda d: d.find_elements(By.ID, "blocked"))[0]
        assert "Measure refused" in banner.text and "Do not measure parts" in banner.text, (path, banner.text)
        assert banner.is_displayed()
        if path == "/":
            assert browser.find_element(By.ID, "measure").get_attribute("aria-disabled") == "true"
        _post(direct + "api/part", {"recipe": "rotor-3"}, bearer)
        wait.until(lambda d: not d.find_elements(By.ID, "blocked"))
    assert running.app.store.count() == 0

    # the appliance unreachable (the daemon runs on) and back: every page greys, its buttons disabled, the time said
    for path in ("/", *PAGES):
        _open(browser, wait, cable.url.rstrip("/") + path)
        pressable = [words for words, enabled in _buttons(browser) if enabled]
        assert pressable, path  # at least "log out"
        cable.pull()
        wait.until(lambda d: _body(d, "data-offline") == "1")
        said = browser.find_element(By.ID, "offline")
        assert said.is_displayed() and UNREACHABLE.search(said.text), (path, said.text)
        assert not [words for words, enabled in _buttons(browser) if enabled], (path, _buttons(browser))
        assert _all_grey(browser), path
        if path == "/":
            assert browser.find_element(By.ID, "state").text == "NO CONNECTION"
            assert not browser.find_element(By.ID, "measure").is_enabled()
        cable.plug()
        wait.until(lambda d: _body(d, "data-offline") is None)
        assert [words for words, enabled in _buttons(browser) if enabled] == pressable, path
        assert not browser.find_element(By.ID, "offline").is_displayed()
        assert not browser.find_elements(By.CSS_SELECTOR, "#restarted[data-restarted]"), path  # the same daemon
        if path == "/":
            wait.until(lambda d: d.find_element(By.ID, "state").text == "IDLE")

    # the daemon restarted under an open page with a part in hand: said, the login gone, the page served again
    through_reload = WebDriverWait(browser, 60, poll_frequency=0.05, ignored_exceptions=(WebDriverException,))
    for path in PAGES[:2]:
        _post(running.app.web.url + "api/part", {"recipe": "rotor-3", "part_id": "SN-1006"}, bearer)
        _post(running.app.web.url + "api/measure", {}, bearer)
        running.wait_done(1, 60)  # one release of three: the part in hand
        _open(browser, wait, cable.url.rstrip("/") + path)
        if not browser.find_elements(By.ID, "who"):  # logged out by the restart before
            _log_in(browser, wait, Path(running.app.web.token_file).read_text().strip())
            wait.until(lambda d: _body(d, "data-live") == "1")
        wait.until(lambda d: d.execute_script("return document.getElementById('who') !== null"))
        running.stop()
        wait.until(lambda d: _body(d, "data-offline") == "1")
        running = appliance_factory(doc)
        cable.target = int(running.app.web.url.rstrip("/").rsplit(":", 1)[1])
        # read in one script: the page reloads itself meanwhile, and a node found by one call may be gone by the next
        told = through_reload.until(lambda d: d.execute_script(
            "var m = document.getElementById('restarted');"
            " return m && m.getAttribute('data-restarted') === '1' ? m.innerText : null"))
        assert "The appliance restarted" in told, (path, told)
        assert "the part in hand SN-1006 (release 1 of 3 done) was not finished" in told, (path, told)
        assert "log in again" in told, (path, told)
        wait.until(lambda d: _body(d, "data-live") == "1")
        # the header no longer shows a login the new daemon does not have; the page is the new daemon's
        assert not browser.find_elements(By.ID, "who") and browser.find_element(By.ID, "login-button").is_displayed()
        assert browser.execute_script("return location.pathname") == path
        meta = browser.execute_script("return document.querySelector('meta[name=moi-boot]').content")
        assert meta == _boot(running.app.web.url)
        assert _body(browser, "data-offline") is None and browser.find_element(By.ID, "restarted").is_displayed()


#: a number and the unit of inertia after it, as the pages write them
INERTIA = re.compile(r"(−?-?\d[\d ]*(?:\.\d+)?) ?(kg·m²|g·cm²|kg·mm²|kg·cm²|g·mm²|lb·in²|lb·ft²)")


def _decimals_ok(number: str, places: int) -> bool:
    """A number written with the recipe's decimals, or (below 10 of its unit) with at most two significant digits,
    as a small uncertainty is written rather than as 0 (0.5: a trailing zero dropped)."""
    import math

    digits = number.split(".")[1] if "." in number else ""
    v = abs(float(number.replace("−", "-").replace(" ", "")))
    return len(digits) == places or (0 < v < 10 and len(digits) <= max(places, 1 - math.floor(math.log10(v))))


def _in_unit(text: str, unit: str, places: int) -> list[str]:
    """Every inertia written in ``text``, checked to be in ``unit`` with ``places`` decimals (failing with the first
    that is not); at least one must be there."""
    found = INERTIA.findall(text)
    assert found, text
    for number, written in found:
        assert written == unit and _decimals_ok(number, places), (number, written, text)
    return [n for n, _ in found]


@pytest.fixture
def shop(appliance_factory, tmp_path, berlin):
    """Named users (an admin, an operator, two quality engineers) and two part types shown in g·cm² with 0
    decimals, one whose nominal is 20 % off (NOK), one whose 1σ limit no release meets (INVALID)."""
    from service.publish.web.auth import User, hash_password, save_users

    users = tmp_path / "users.toml"
    save_users(users, {"root": User("root", "admin", hash_password("root-password-1")),
                       "olga": User("olga", "operator", hash_password("olga-password-1")),
                       **{n: User(n, "quality", hash_password(f"{n}-password-1")) for n in ("quinn", "rita")}})
    d = tmp_path / "recipes"
    d.mkdir()
    (d / "g.toml").write_text('[recipe]\nname = "rotor-g"\nnumber = 5\nnominal = 0.015\ntolerance_percent = 2.0\n'
                              'display_unit = "g·cm²"\ndisplay_decimals = 0\n')
    (d / "gi.toml").write_text('[recipe]\nname = "rotor-gi"\nnumber = 6\nnominal = 0.0125\ntolerance_percent = 2.0\n'
                               'display_unit = "g·cm²"\ndisplay_decimals = 0\n[quality]\nmax_J_std = 1.0e-15\n')
    running = appliance_factory(appliance_doc(tmp_path / "state", time_scale=5.0,
                                              web={"enabled": True, "users_file": str(users)},
                                              recipes={"directory": str(d), "active": "rotor-g"}))
    return running, users, d / "g.toml", tmp_path / "state"


def test_the_reviews_figures_as_the_browser_shows_them(browser, shop):  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    from service.publish.dfq import FIELD
    from service.publish.quality import local_time
    from tests.service.publish.web.test_service_web_admin import _form, _quality

    running, users, recipe_file, state = shop
    app = running.app
    url = app.web.url
    token = Path(app.web.token_file).read_text().strip()
    bearer = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    for recipe, part in (("rotor-g", "SN-2000"), ("rotor-g", "SN-2001"), ("rotor-gi", "SN-2002")):
        _post(url + "api/part", {"recipe": recipe, "part_id": part}, bearer)
        done = app.store.count()
        _post(url + "api/measure", {}, bearer)
        running.wait_done(done + 1, 60)
    first, nok, invalid = app.store.list(parts_only=True, limit=3, full=True)[::-1]
    assert (first.part_verdict, nok.part_verdict, invalid.part_verdict) == ("NOK", "NOK", "INVALID")
    wait = WebDriverWait(browser, 60, poll_frequency=0.05)
    browser.set_window_size(1280, 800)
    _open(browser, wait, url)
    _log_in(browser, wait, token)  # the appliance's token: the admin

    # Home: every number of the part in hand's tile in g·cm² with 0 decimals, the INVALID reason's too
    tile = browser.find_element(By.ID, "now").text
    assert "INVALID" in tile and "SN-2002" in tile and "kg·m²" not in tile
    reasons = browser.find_element(By.ID, "tile-reasons").text
    assert "standard uncertainty" in reasons, reasons
    _in_unit(reasons, "g·cm²", 0)
    _in_unit(tile, "g·cm²", 0)

    # the result pages: the verdict, its reasons, the limits, this release, in g·cm² with 0 decimals
    for m, verdict, why in ((nok, "NOK", "reasons"), (invalid, "INVALID", "excluded")):
        browser.get(url + f"results/{m.uuid}")
        head = wait.until(lambda d: d.find_element(By.CSS_SELECTOR, "section.result-head")).text
        assert browser.find_element(By.ID, "verdict").text.split()[0] == verdict
        assert "kg·m²" not in head
        _in_unit(browser.find_element(By.ID, why).text, "g·cm²", 0)  # the NOK's reason, the INVALID's exclusion
        _in_unit(head, "g·cm²", 0)
        _in_unit(browser.find_element(By.ID, "release").text, "g·cm²", 0)
    browser.get(url + f"results/{nok.uuid}")
    assert re.fullmatch(r"J = \d+ g·cm² ± \d+ g·cm² \(U, k = 2\)", browser.find_element(By.ID, "J").text)
    assert "below LSL" in browser.find_element(By.ID, "why").text

    # the uncertainty budget: each sensitivity with its unit in the page's unit, shares in % summing to 100 %
    tables = browser.find_elements(By.CSS_SELECTOR, "#uncertainty-budget table.budget-table")
    assert tables
    _in_unit(browser.find_element(By.CSS_SELECTOR, "#uncertainty-budget h3").text, "g·cm²", 0)  # J, U and u
    for table in tables:  # one per measurand
        rows = [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
                for tr in table.find_elements(By.CSS_SELECTOR, "tr.budget-row")]
        assert len(rows) >= 3, rows
        assert all(re.fullmatch(r"\d+\.\d %", r[1]) for r in rows), rows  # in %, never a fraction nor negative
        shares = [float(r[1].split()[0]) for r in rows]
        assert all(s >= 0 for s in shares) and abs(sum(shares) - 100.0) <= 0.05 * len(shares) + 1e-9, shares
        lines = rows + [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
                        for tr in table.find_elements(By.CSS_SELECTOR, "tr.budget-member")]
        per = [r[5] for r in lines if len(r) == 6]  # a correlated group's row: its members' lines below it
        assert per and all(re.fullmatch(r"−?-?[\d.]+ g·cm²( per \S+)?", c) for c in per), per
        assert any(" per N·m/rad" in c for c in per), per
        assert "contribution c·u [g·cm²]" in table.text

    # the DFQ of the SPC page: its times in the appliance's local time, as the history page writes them
    browser.get(url + "spc?recipe=rotor-g")
    href = wait.until(lambda d: d.find_element(By.ID, "dfq-link")).get_attribute("href")
    dfq = browser.execute_async_script("var done = arguments[arguments.length - 1];"
                                       " fetch(arguments[0]).then(r => r.text()).then(done, e => done(String(e)));", href)
    times = [ln.split(FIELD)[2] for ln in dfq.split("\r\n") if FIELD in ln]
    assert times == [local_time(m.finished_at, "%d.%m.%Y/%H:%M:%S") for m in (first, nok)], dfq
    import datetime as dt

    utc = dt.datetime.fromtimestamp(nok.finished_at, dt.UTC)
    assert times[1] != utc.strftime("%d.%m.%Y/%H:%M:%S")  # Berlin is never UTC
    browser.get(url + "history?recipe=rotor-g")
    wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#history td.when"))
    shown = [td.text for td in browser.find_elements(By.CSS_SELECTOR, "#history td.when")][::-1]  # newest first
    assert [dt.datetime.strptime(t, "%Y-%m-%d %H:%M:%S").strftime("%d.%m.%Y/%H:%M:%S") for t in shown] == times

    # a 31-character scan: refused with its length said, nothing cut, the part ID unchanged
    _open(browser, wait, url)
    browser.find_element(By.CSS_SELECTOR, "#part-box summary").click()
    scanned = "SN-2026-11-28-LINE3-0000123456X"
    field = wait.until(lambda d: d.find_element(By.ID, "part-id-input"))
    field.send_keys(scanned)
    browser.find_element(By.ID, "part-set").click()
    said = wait.until(lambda d: d.find_element(By.ID, "part-id-error").text)
    assert said == "31 characters: a part ID holds at most 20 (nothing was cut: check the scan)", said
    assert field.get_attribute("value") == scanned and field.get_attribute("aria-invalid") == "true"
    assert browser.find_element(By.ID, "part-id").text == "SN-2002" and app.parts.part_id == "SN-2002"

    # two admins at once: the browser's users form, opened before the other's change, is refused (409) and
    # nothing is written; the other's change is the one audit line
    from service.publish.web.auth import read_users

    browser.get(url + "users")
    wait.until(lambda d: d.find_element(By.ID, "user-form"))
    other = Client(url)
    other.request("/login", {"token": token, "csrf": other.csrf()})
    page = other.request("/users")[2].decode()
    version = page.split('name="version" value="')[1].split('"')[0]
    csrf = page.split('name="csrf-token" content="')[1].split('"')[0]
    assert other.request("/users", {"action": "disable", "name": "olga", "version": version, "csrf": csrf})[0] == 200
    browser.find_element(By.ID, "new-name").send_keys("olga")
    from selenium.webdriver.support.ui import Select

    Select(browser.find_element(By.ID, "new-role")).select_by_visible_text("quality")
    browser.find_element(By.CSS_SELECTOR, "#user-form button[value=change]").click()
    said = wait.until(lambda d: d.find_elements(By.ID, "users-error"))[0].text
    assert "changed since you opened this page" in said and "nothing was changed" in said, said
    assert browser.execute_script("return performance.getEntriesByType('navigation')[0].responseStatus") == 409
    assert read_users(users)["olga"].role == "operator" and read_users(users)["olga"].disabled
    audit = (state / "users-audit.log").read_text().splitlines()
    assert [line.split("\t")[1:4] for line in audit] == [["web", "disabled", "olga"]], audit

    # two editors of one recipe: the browser's form, opened before quinn's edit, is refused (409) and audited
    browser.get(url + "recipes")
    wait.until(lambda d: d.find_element(By.ID, "edit-5"))
    quinn, page = _quality(app, "quinn")
    assert quinn.request("/recipes", {**_form(page), "releases": "3"})[0] == 200
    browser.find_element(By.CSS_SELECTOR, "#recipe-5 details.recipe-edit summary").click()
    nominal = wait.until(lambda d: d.find_element(By.ID, "edit-5-nominal"))
    assert nominal.get_attribute("value") == "150000"  # in the recipe's g·cm²
    nominal.clear()
    nominal.send_keys("151000")
    browser.find_element(By.CSS_SELECTOR, "#edit-5 button[type=submit]").click()
    said = wait.until(lambda d: d.find_elements(By.ID, "recipe-error"))[0].text
    assert "changed since you opened it" in said and "nothing was saved" in said, said
    assert browser.execute_script("return performance.getEntriesByType('navigation')[0].responseStatus") == 409
    text = recipe_file.read_text()
    assert "releases = 3" in text and "nominal = 0.015" in text
    lines = [line.split("\t")[1:] for line in (state / "recipe-audit.log").read_text().splitlines()]
    assert lines[-1] == ["web", "rotor-g", "g.toml", "refused: the file changed since the form was opened → nothing "
                                                     "written"], lines
    assert lines[-2][0] == "web:quinn" and len(lines) == 2


def test_a_page_left_gives_its_live_stream_back(browser, appliance_factory, tmp_path):  # noqa: F811
    """Going from page to page, more pages than one address may hold streams: none is refused its stream (the
    browser keeps a page left for "back", and its stream with it, unless the page gives it back)."""
    from selenium.webdriver.support.ui import WebDriverWait

    from tests.service.conftest import wait_until

    running = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True}))
    web = running.app.web
    wait = WebDriverWait(browser, 60, poll_frequency=0.05)
    browser.set_window_size(390, 844)
    per_client = web.settings.max_streams_per_client
    for i in range(2 * per_client + 1):
        _open(browser, wait, web.url + ("history", "calibration", "")[i % 3])
        # the server learns of a closed stream at its next write (a tick): each page left has given its stream
        # back before the next is opened, so no refusal below depends on how fast the host is
        wait_until(lambda: web.streams.open == 1, 30, what=f"page {i + 1}'s stream alone, the page left's given back")
    assert web.streams.refused == 0
    browser.back()  # the page before, shown again (from the browser's cache): its stream opened again
    wait.until(lambda d: d.execute_script("return location.pathname") == "/calibration")
    browser.execute_script("document.body.removeAttribute('data-live')")
    wait.until(lambda d: _body(d, "data-live") == "1")  # a tick arrived
    assert web.streams.refused == 0
