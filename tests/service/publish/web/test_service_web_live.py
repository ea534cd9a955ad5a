"""Home kept open on a phone (390×844) and a desktop (1280×800) in headless Chromium while the appliance changes under it: a calibration
block pushed to the open page, a double click on Measure, the appliance going down (the page greys, Measure
disabled, the time said) and coming back restarted (the page says what was lost: the part in hand, the login)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.service.publish.web.test_service_web import _three_release_doc
from tests.service.publish.web.test_service_web_browser import _post, browser  # noqa: F401 (the fixture)

pytestmark = pytest.mark.browser


@pytest.mark.parametrize("size", [(390, 844), (1280, 800)], ids=("phone", "desktop"))
def test_the_open_home_page_follows_a_block_an_outage_and_a_restart(browser, appliance_factory, tmp_path,  # noqa: F811
                                                                     size):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    doc = _three_release_doc(tmp_path)
    first = appliance_factory(doc)
    url = first.app.web.url
    token = Path(first.app.web.token_file).read_text().strip()
    bearer = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    from selenium.common.exceptions import StaleElementReferenceException

    # the page reloads itself after a restart: an element found just before the reload is gone when read
    wait = WebDriverWait(browser, 30, poll_frequency=0.05, ignored_exceptions=(StaleElementReferenceException,))
    browser.set_window_size(*size)
    browser.get(url)
    browser.find_element(By.ID, "token").send_keys(token)
    browser.find_element(By.ID, "login-button").click()
    wait.until(lambda d: d.find_elements(By.ID, "who"))
    wait.until(lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-live") == "1")

    # the PLC selects a recipe whose rig's calibration expired: the banner and a refused Measure, without a press
    _post(url + "api/part", {"recipe": "rotor-cal"}, bearer)
    wait.until(lambda d: d.find_elements(By.ID, "blocked"))
    assert browser.find_element(By.ID, "measure").get_attribute("aria-disabled") == "true"
    assert "Do not measure parts" in browser.find_element(By.ID, "blocked").text
    _post(url + "api/part", {"recipe": "rotor-3", "part_id": "SN-1006"}, bearer)
    wait.until(lambda d: not d.find_elements(By.ID, "blocked") and d.find_element(By.ID, "part-id").text == "SN-1006")
    assert browser.find_element(By.ID, "measure").get_attribute("aria-disabled") is None

    # a double click measures once, and says nothing of a measurement "already running" while IDLE
    ActionChains(browser).double_click(browser.find_element(By.ID, "measure")).perform()
    first.wait_done(1, 60)
    wait.until(lambda d: d.find_element(By.ID, "release-k").text == "next: release 2 of 3")
    assert "already" not in browser.find_element(By.ID, "message").text
    assert first.app.store.count() == 1

    # the appliance goes down: the page greys, Measure is disabled, and it says since when
    first.stop()
    wait.until(lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-offline") == "1")
    said = browser.find_element(By.ID, "offline").text
    assert re.search(r"appliance not reachable since \d\d:\d\d:\d\d", said), said
    assert not browser.find_element(By.ID, "measure").is_enabled()
    assert browser.find_element(By.ID, "state").text != "IDLE"

    # it comes back, restarted: the page is served again and says what was lost; no verdict as the part in hand's
    doc["web"]["port"] = int(url.rstrip("/").rsplit(":", 1)[1])
    second = appliance_factory(doc)
    assert second.app.web.url == url
    # read in one script: the page reloads itself meanwhile, and a node found by one call may be gone by the next
    # (Chromium's "stale element" or "node does not belong to the document")
    from selenium.common.exceptions import WebDriverException

    through_reload = WebDriverWait(browser, 30, poll_frequency=0.05, ignored_exceptions=(WebDriverException,))
    told = through_reload.until(lambda d: d.execute_script(
        "var m = document.getElementById('restarted');"
        " return m && m.getAttribute('data-restarted') === '1' ? m.innerText : null"))
    assert "The appliance restarted" in told and "SN-1006 (release 1 of 3 done) was not finished" in told, told
    assert "log in again" in told and browser.find_elements(By.ID, "login-button")
    wait.until(lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-live") == "1")
    assert browser.find_element(By.ID, "measure").is_enabled()
    assert browser.find_element(By.TAG_NAME, "body").get_attribute("data-offline") is None
    assert not browser.find_elements(By.ID, "tile-verdict")
    assert browser.find_element(By.ID, "state").text == "IDLE"
