"""What Home's live stream and JSON carry for a page kept open: the daemon's life (a restart is seen, and an older
part's verdict is never the part in hand's), a calibration block as it starts, and a refused second Measure that
names the state it refers to."""

from __future__ import annotations

import json
import re
import urllib.request
from pathlib import Path

from service.states import STATES
from tests.service.conftest import appliance_doc, wait_until
from tests.service.publish.web.test_service_web import ON, Client, _measure, _recipes


def _ticks(url: str):
    """The ``tick`` events of the live stream at ``url``, as they come (the connection closed when the caller stops)."""
    with urllib.request.urlopen(url, timeout=30) as r:
        event = None
        for raw in r:
            line = raw.decode().rstrip("\n")
            if line.startswith("event: "):
                event = line[7:]
            elif line.startswith("data: ") and event == "tick":
                yield json.loads(line[6:])


def _first_tick(url: str) -> dict:
    """The first ``tick`` of the live stream, the connection closed after it."""
    for tick in _ticks(url.rstrip("/") + "/events"):
        return tick
    raise AssertionError("the stream ended without a tick")


def _capture_ticks(url: str, n: int) -> list[dict]:
    """``n`` ticks of the stream at ``url`` taken during a capture, the connection closed after them."""
    ticks = []
    for tick in _ticks(url):
        if tick["state"] == "CAPTURING" and tick.get("elapsed", 0) > 0:
            ticks.append(tick)
            if len(ticks) == n:
                return ticks
    raise AssertionError(f"the stream ended after {len(ticks)} ticks of the capture")


def _boot_of_page(c: Client) -> str:
    return c.request("/")[2].decode().split('name="moi-boot" content="')[1].split('"')[0]


def test_a_restart_is_seen_in_the_stream_and_the_previous_verdict_is_not_the_part_in_hand(appliance_factory,
                                                                                          tmp_path):
    recipes = _recipes(tmp_path / "recipes")
    doc = appliance_doc(tmp_path / "state", web=ON, recipes={"directory": str(recipes), "active": "rotor-nok"})
    first = appliance_factory(doc)
    bearer = {"Authorization": f"Bearer {Path(first.app.web.token_file).read_text().strip()}"}
    c = Client(first.app.web.url)
    _measure(first, c, bearer, "rotor-nok", "SN-1005", 1)
    home = c.request("/")[2].decode()
    assert 'id="tile-verdict"' in home and "SN-1005" in home  # the part just measured: its verdict, big
    boot = _boot_of_page(c)
    url = first.app.web.url
    assert boot and _first_tick(url)["boot"] == boot == c.json("/api/state")[1]["boot"]
    first.stop()

    doc["web"]["port"] = int(url.rstrip("/").rsplit(":", 1)[1])  # the page's address, again
    second = appliance_factory(doc)
    assert second.app.web.url == url
    tick = _first_tick(second.app.web.url)
    assert tick["boot"] != boot and _boot_of_page(c) == tick["boot"]
    home = c.request("/")[2].decode()
    # the part finished before the restart is a previous part, not the verdict of the part in hand
    assert 'id="tile-verdict"' not in home and 'class="now now-ready"' in home
    assert re.search(r"previous part: <a [^>]+>SN-1005 NOK</a>", home), home


def test_a_calibration_block_reaches_the_live_stream_as_it_starts(appliance_factory, tmp_path):
    recipes = _recipes(tmp_path / "recipes")
    running = appliance_factory(appliance_doc(tmp_path / "state", web=ON,
                                              recipes={"directory": str(recipes), "active": "rotor-ok"}))
    bearer = {"Authorization": f"Bearer {Path(running.app.web.token_file).read_text().strip()}"}
    c = Client(running.app.web.url)
    assert _first_tick(running.app.web.url)["measure_refused"] is False
    # the recipe selected elsewhere (the PLC) measures with a rig whose calibration has expired
    assert c.json("/api/part", data={"recipe": "rotor-cal"}, headers=bearer)[0] == 202
    wait_until(lambda: c.json("/api/state")[1]["measure_refused"], 10, what="the block in the state")
    assert _first_tick(running.app.web.url)["measure_refused"] is True
    assert 'id="blocked"' in c.request("/home/summary")[2].decode()


def _long_capture(appliance_factory, tmp_path):
    """An appliance whose capture lasts 300 s (a measurement stays running until aborted), its bearer and a client."""
    doc = appliance_doc(tmp_path / "state", web=ON)
    doc["sequencer"]["capture_duration"] = 300.0
    running = appliance_factory(doc)
    bearer = {"Authorization": f"Bearer {Path(running.app.web.token_file).read_text().strip()}"}
    return running, bearer, Client(running.app.web.url)


def test_a_second_measure_names_the_state_it_refers_to(appliance_factory, tmp_path):
    running, bearer, c = _long_capture(appliance_factory, tmp_path)
    # a double click: the second press right behind the first, before or after the sequencer took it
    assert c.json("/api/measure", method="POST", headers=bearer)[0] == 202
    status, refused = c.json("/api/measure", method="POST", headers=bearer)
    assert status == 409, refused
    said = re.search(r"already running \((\w+)\)", refused["error"])
    assert (said is not None and STATES[said.group(1)].busy) or "already requested and starting" in refused["error"]
    assert c.json("/api/abort", method="POST", headers=bearer)[0] == 202
    running.wait_done(1, 30)


def test_a_page_that_draws_no_swing_is_sent_no_samples(appliance_factory, tmp_path):
    running, bearer, c = _long_capture(appliance_factory, tmp_path)
    assert c.json("/api/measure", method="POST", headers=bearer)[0] == 202
    events = running.app.web.url + "events"
    assert any(t.get("samples", {}).get("t") for t in _capture_ticks(events, 8))  # Home's: the swing as it arrives
    plain = _capture_ticks(events + "?samples=no", 8)  # every other page's: the state alone
    assert not [t for t in plain if "samples" in t]
    assert all(t["measure_refused"] is False and t["boot"] and t["remaining"] > 0 for t in plain)
    assert c.json("/api/abort", method="POST", headers=bearer)[0] == 202
    running.wait_done(1, 30)
