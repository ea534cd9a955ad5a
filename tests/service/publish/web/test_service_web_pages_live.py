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

import re
import socket
import threading
import urllib.request
from pathlib import Path

import pytest

from tests.service.conftest import appliance_doc
from tests.service.publish.web.test_service_web import Client, _recipes
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
    try:
        s.shutdown(socket.SHUT_RDWR)  # wakes a thread blocked in accept() or recv() on it
    except OSError:
        pass
    s.close()


def _boot(appliance_url: str) -> str:
    import json

    with urllib.request.urlopen(appliance_url + "api/state", timeout=30) as r:
        return json.loads(r.read())["boot"]


def _body(browser, attribute: str) -> str | None:
    return browser.execute_script(f"return document.body.getAttribute('{attribute}')")


def _buttons(browser) -> list[tuple[str, bool]]:
    """Every button of the page (its words, whether it can be pressed), hidden ones included."""
    return [tuple(b) for b in browser.execute_script(
        "return Array.from(document.querySelectorAll('button, input[type=submit]')).map("
        "b => [(b.textContent || b.value).trim(), !b.disabled])")]


def _all_grey(browser) -> bool:
    """Whether everything the page shows under its header but the words of the outage is greyed."""
    return browser.execute_script(
        "var shown = Array.from(document.querySelector('main').children).filter("
        " e => e.id !== 'offline' && e.id !== 'restarted' && e.getClientRects().length);"
        " return shown.length > 0 && shown.every(e => getComputedStyle(e).filter.indexOf('grayscale') >= 0);")


def _log_in(browser, wait, token: str) -> None:
    from selenium.webdriver.common.by import By

    browser.find_element(By.ID, "token").send_keys(token)
    browser.find_element(By.ID, "login-button").click()
    wait.until(lambda d: d.find_elements(By.ID, "who"))


def _open(browser, wait, url: str) -> None:
    """``url`` open and its live stream connected (its first tick arrived)."""
    browser.get(url)
    wait.until(lambda d: _body(d, "data-live") == "1")


@pytest.fixture
def rig(appliance_factory, tmp_path):
    """The simulated rig with the shared recipes and a three-release part type, reached through a cable."""
    recipes = _recipes(tmp_path / "recipes")
    (recipes / "three.toml").write_text('[recipe]\nname = "rotor-3"\nnumber = 5\nnominal = 0.0125\n'
                                        'tolerance_percent = 2.0\nreleases = 3\n')
    doc = appliance_doc(tmp_path / "state", time_scale=5.0, web={"enabled": True},
                        recipes={"directory": str(recipes), "active": "rotor-3"})
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
