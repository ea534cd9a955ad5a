"""The web page over HTTP (urllib on loopback): who may act, clear 4xx answers, history filters, the plot kept
with the measurement, secrets masked, the token file."""

from __future__ import annotations

import io
import json
import os
import re
import stat
import urllib.error
import urllib.request
from http.cookiejar import CookieJar
from pathlib import Path

import pytest

from service.errors import StartupError
from tests.service.conftest import appliance_doc, login_from, wait_until

ON = {"enabled": True}


class Client:
    def __init__(self, url: str) -> None:
        self.base = url.rstrip("/")
        self.jar = CookieJar()
        self.opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(self.jar))

    def csrf(self) -> str:
        """The page's CSRF value (before a login: the login form's)."""
        html = self.request("/")[2].decode()
        return html.split('name="csrf-token" content="')[1].split('"')[0]

    def request(self, path: str, data: dict | bytes | None = None, headers: dict | None = None,
                method: str | None = None, timeout: float = 30) -> tuple[int, dict, bytes]:
        body = data if isinstance(data, bytes) or data is None else urllib.parse.urlencode(data).encode()
        req = urllib.request.Request(self.base + path, data=body, headers=headers or {}, method=method)
        try:
            with self.opener.open(req, timeout=timeout) as r:
                return r.status, dict(r.headers), r.read()
        except urllib.error.HTTPError as e:
            return e.code, dict(e.headers), e.read()

    def json(self, path: str, **kw) -> tuple[int, dict]:
        status, _, body = self.request(path, headers={"Accept": "application/json", **kw.pop("headers", {})}, **kw)
        return status, json.loads(body)


@pytest.fixture
def running(appliance_factory, tmp_path):
    return appliance_factory(appliance_doc(tmp_path / "state", web=ON))


def test_actions_need_the_token_and_the_csrf_token(running):
    app = running.app
    token = Path(app.web.token_file).read_text().strip()
    assert stat.S_IMODE(os.stat(app.web.token_file).st_mode) == 0o600  # made on first start, owner only
    c = Client(app.web.url)
    assert c.json("/api/measure", method="POST") == (401, {"error": "log in first: this action needs the "
                                                          "appliance's token", "status": 401})
    assert c.json("/api/measure", method="POST", headers={"Authorization": "Bearer wrong-token"})[0] == 401
    # a login form without the form's CSRF value (what a forged cross-site form would be): refused
    assert c.request("/login", {"token": token})[0] == 403
    login_csrf = c.csrf()
    status, _, body = c.request("/login", {"token": "wrong-token", "csrf": login_csrf})
    assert status == 401 and b"wrong token" in body and b"Traceback" not in body
    # logged in, but without the page's CSRF token: the actions below are refused
    status, _, _ = c.request("/login", {"token": token, "next": "/setup", "csrf": login_csrf})
    assert status == 200
    # after a login only a page of this appliance: never a redirect to another site
    no_follow = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(c.jar), type(
        "NoRedirect", (urllib.request.HTTPRedirectHandler,), {"redirect_request": lambda *a, **k: None}))
    for target in ("//evil.example/", "/\\evil.example/", "http://evil.example/"):
        req = urllib.request.Request(app.web.url + "login", data=urllib.parse.urlencode(
            {"token": token, "next": target, "csrf": login_csrf}).encode())
        with pytest.raises(urllib.error.HTTPError) as got:
            no_follow.open(req, timeout=10)
        assert (got.value.code, got.value.headers["Location"]) == (303, "/")
    assert c.json("/api/measure", method="POST")[0] == 403
    assert c.json("/api/abort", method="POST", headers={"X-CSRF-Token": "guess"})[0] == 403
    # another site's page naming this appliance: refused whatever it carries
    html = c.request("/")[2].decode()
    csrf = html.split('name="csrf-token" content="')[1].split('"')[0]
    assert len(csrf) > 20
    assert c.json("/api/measure", method="POST", headers={"X-CSRF-Token": csrf,
                                                         "Origin": "http://evil.example"})[0] == 403
    assert app.store.count() == 0 and not app.sequencer.busy
    # with it: accepted, and the measurement runs
    status, doc = c.json("/api/measure", method="POST", headers={"X-CSRF-Token": csrf})
    assert (status, doc["accepted"]) == (202, True)
    running.wait_done(1, 60)
    assert app.store.latest().trigger == "web"
    # a script with the token as a bearer: no session, no CSRF needed
    assert Client(app.web.url).json("/api/abort", method="POST",
                                    headers={"Authorization": f"Bearer {token}"})[0] == 202


def test_result_plot_kept_history_filters_and_clear_errors(running):
    app = running.app
    running.press()
    running.wait_done(1, 60)
    m = app.store.latest()
    c = Client(app.web.url)
    status, headers, png = c.request(f"/results/{m.uuid}/plot.png")
    assert status == 200 and headers["Content-Type"] == "image/png" and png[:4] == b"\x89PNG"
    assert app.store.get_attachment(m.uuid, "plot.png")[0] == png  # drawn once, kept with the measurement
    assert app.web.child.jobs >= 1  # in the child process, away from the sensor's reader
    status, _, page = c.request(f"/results/{m.seq}")
    assert status == 200
    shown = page.decode().split('id="J-release">')[1].split(" ± ")[0]  # J in the part's unit and decimals
    assert shown.endswith(" kg·m²") and abs(float(shown.split()[0].replace("\u2212", "-")) / m.J - 1) < 1e-4
    # the uncertainty budget: a table per measurand, each line's share as a bar
    budget = page.decode().split('id="uncertainty-budget"')[1]
    assert "stiffness k (calibration)" in budget and "<meter" in budget and "U = " in budget
    # the model before and after, and the noise floor: the stored result's fields
    from service.publish.payload import stored_result
    from service.publish.quality import number

    r = stored_result(m.payload)
    assert r is not None
    model = page.decode().split('class="model"')[1].split("</table>")[0]
    assert number(r.baseline.omega_n, ".7g") in model and number(r.statistics["bic"], ".1f") in model
    assert f"<td>{shown}</td>" in model  # the final model's J written as the headline writes it, not to 7 digits
    assert f"noise floor {number(r.noise_floor, '.3g')} rad" in page.decode()
    status, _, csv_text = c.request(f"/results/{m.uuid}/trace.csv")
    assert status == 200 and b"t,angle" in csv_text
    status, doc = c.json(f"/results/{m.uuid[:8]}/result.json")
    assert status == 200 and doc["uuid"] == m.uuid and doc["J"] == m.J
    # history: newest first, filters in the query
    assert m.uuid.encode() in c.request("/history")[2]
    assert m.uuid.encode() not in c.request("/history?status=failed")[2]
    assert m.uuid.encode() not in c.request("/history?since=2999-01-01")[2]
    assert m.uuid.encode() not in c.request("/history?flag=fit_not_converged")[2]
    assert m.uuid.encode() not in c.request("/history?part=no-such-part")[2]
    status, _, export = c.request("/history/export.json?status=ok")
    assert status == 200 and [r["uuid"] for r in json.loads(export)] == [m.uuid]
    # bad requests: 4xx with what was wrong, never a traceback
    for path, code, words in (("/history?since=yesterday", 400, b"expected a date YYYY-MM-DD"),
                              ("/history?page=0", 400, b"page number"),
                              ("/history?page=999", 404, b"page 999: the history has 1 page of"),
                              ("/history?status=maybe", 400, b"expected ok, failed or aborted"),
                              ("/results/no-such-id", 404, b"no measurement"),
                              ("/results/a%27b", 400, b"bad measurement id"),
                              ("/history/export.xml", 404, b"expected export.csv, export.json or export.dfq"),
                              ("/nothing-here", 404, b"no page")):
        status, _, body = c.request(path)
        assert (status, words in body, b"Traceback" in body) == (code, True, False), (path, status, body[:300])
    status, doc = c.json("/api/measure", method="GET")
    assert status == 405 and "not allowed" in doc["error"]


def test_setup_page_masks_secrets_and_reports_health(appliance_factory, tmp_path):
    token_file = tmp_path / "token"
    token_file.write_text("a-long-enough-token\n")
    doc = appliance_doc(tmp_path / "state", web={**ON, "token_file": str(token_file)})
    running = appliance_factory(doc)
    c = Client(running.app.web.url)
    status, _, page = c.request("/setup")
    assert status == 200 and b"a-long-enough-token" not in page and b"client(s) connected" in page
    # the configuration in words, not JSON; no file or folder of the appliance shown to a visitor
    text = page.decode()
    assert "request timeout" in text and "null" not in text and '": ' not in text
    assert str(token_file) not in text and str(tmp_path) not in text and "shown after logging in" in text
    # the simulated in-process sensor has no one-off reading: no button that would only fail
    assert 'id="angle-button"' not in text and 'id="angle-none"' in text
    c.request("/login", {"token": "a-long-enough-token", "csrf": c.csrf()})
    assert str(token_file) in c.request("/setup")[2].decode()  # logged in: where the token is
    status, health = c.json("/api/health")
    assert status == 200 and health["modbus"]["clients"] == 0 and health["disk"]["free_bytes"] > 0
    assert Client(running.app.web.url).json("/api/abort", method="POST", headers={
        "Authorization": "Bearer a-long-enough-token"})[0] == 202


def test_a_missing_token_file_stops_the_start(tmp_path):
    from service.config.appliance import parse_config
    from service.daemon import Appliance

    doc = appliance_doc(tmp_path / "state", web={**ON, "token_file": str(tmp_path / "absent")})
    app = Appliance(parse_config(doc, source="test.toml"))
    with pytest.raises(StartupError, match="absent.*does not exist"):
        app.start()
    assert app.devices is None and app.store is None  # everything started was shut down again


def test_store_search_pages_and_filters(tmp_path):
    from service.persistence.store import Store

    with Store(tmp_path) as store:
        for i in range(7):
            store.record(status="ok", trigger="test", device_id="d", software_version="0", started_at=100.0 + i,
                         finished_at=101.0 + i, result={"J": 0.01 + i, "flags": ["outliers_removed"] if i == 3 else []},
                         build_payload=lambda uuid, seq: {"uuid": uuid, "seq": seq},
                         part={"recipe": "rotor-a" if i % 2 else "rotor-b", "part_id": f"P{i}"})
        rows, total = store.search(offset=2, limit=2)
        assert total == 7 and [m.seq for m in rows] == [5, 4]  # newest first, the second page
        rows, total = store.search(recipe="rotor-a")
        assert total == 3 and {m.seq for m in rows} == {2, 4, 6}
        assert [m.seq for m in store.search(part_id="P3")[0]] == [4]
        assert [m.seq for m in store.search(flag="outliers_removed")[0]] == [4]
        assert store.search(since=105.0, until=107.0)[1] == 2
        store.put_attachment(rows[0].uuid, "plot.png", b"\x89PNG...", "image/png")
        assert store.get_attachment(rows[0].uuid, "plot.png") == (b"\x89PNG...", "image/png")
        assert store.get_attachment(rows[0].uuid, "other") is None


def test_a_taken_port_stops_the_start_with_a_clear_reason(tmp_path):
    import socket

    from service.config.appliance import parse_config
    from service.daemon import Appliance

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        app = Appliance(parse_config(appliance_doc(tmp_path / "state", web={**ON, "port": port}), source="t.toml"))
        with pytest.raises(StartupError, match=f"cannot serve the web page on 127.0.0.1:{port}"):
            app.start()
    assert app.web is None and app.store is None


def test_setup_camera_snapshot_and_fault_shown_and_acknowledged(appliance_factory, tmp_path):
    running = appliance_factory(appliance_doc(tmp_path / "state", time_scale=1.0, web=ON,
                                              simulation={"sensor": "camera"}))
    app = running.app
    c = Client(app.web.url)
    assert b"snapshot-button" in c.request("/setup")[2]
    status, headers, png = c.request("/setup/snapshot.png")
    assert status == 200 and headers["Content-Type"] == "image/png" and png[:4] == b"\x89PNG"
    import cv2
    import numpy as np
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None and img.shape[:2] == (480, 640)
    # the fitted edge is drawn in red (B, G, R = 0, 0, 255): the marker was found in the frame
    assert np.count_nonzero((img[:, :, 2] == 255) & (img[:, :, 1] == 0) & (img[:, :, 0] == 0)) > 20
    # a FAULT is shown with its reason; the token acknowledges it
    app.sequencer.fault("encoder fault: test cable pulled")
    running.wait_event(lambda e: e.state.value == "FAULT", 10, what="FAULT")
    status, state = c.json("/api/state")
    assert state["state"] == "FAULT" and state["fault"] == "encoder fault: test cable pulled"
    token = Path(app.web.token_file).read_text().strip()
    assert c.json("/api/abort", method="POST", headers={"Authorization": f"Bearer {token}"})[0] == 202
    running.wait_event(lambda e: e.state.value == "IDLE" and e.previous.value == "ABORTED", 10, what="acknowledged")


def test_a_snapshot_asked_before_the_sequencer_exists_is_refused_plainly():
    # the devices built but no sequencer yet (or no longer): a clear 503, never an AttributeError's text
    import asyncio
    import concurrent.futures
    from types import SimpleNamespace

    from service.publish.web.pages import Refused
    from service.publish.web.set_up import SetUpPages

    def call_soon(fn):
        fut: concurrent.futures.Future = concurrent.futures.Future()
        try:
            fut.set_result(fn())
        except Exception as exc:
            fut.set_exception(exc)
        return fut

    setup = SetUpPages.__new__(SetUpPages)
    setup.app = SimpleNamespace(  # type: ignore[assignment]
        config=SimpleNamespace(simulated=True, simulation=SimpleNamespace(sensor="camera", camera_config=object())),
        devices=SimpleNamespace(sensor=SimpleNamespace(camera=object())), sequencer=None, call_soon=call_soon)
    with pytest.raises(Refused) as got:
        asyncio.run(setup.snapshot(None))  # type: ignore[arg-type]
    assert got.value.status_code == 503 and got.value.message == "the appliance is not running its devices yet"


def test_setup_encoder_angle_now(appliance_factory, tmp_path):
    running = appliance_factory(appliance_doc(tmp_path / "state", web=ON, simulation={"sensor": "encoder", "time_scale": 1.0}))
    status, body = Client(running.app.web.url).json("/api/angle")
    # the simulated pendulum is held at its release angle (0.25 rad) until a measurement fires the solenoid
    assert status == 200 and body["source"] == "encoder" and body["angle_rad"] == pytest.approx(0.25, abs=1e-3)


def test_recipe_and_part_id_set_from_the_page_reach_the_result_and_the_history(appliance_factory, tmp_path):
    d = tmp_path / "recipes"
    d.mkdir()
    (d / "a.toml").write_text('[recipe]\nname = "rotor-a"\nnumber = 3\nnominal = 0.0125\ntolerance_percent = 2.0\n')
    running = appliance_factory(appliance_doc(tmp_path / "state", web=ON, recipes={"directory": str(d)}))
    app = running.app
    bearer = {"Authorization": f"Bearer {Path(app.web.token_file).read_text().strip()}"}
    c = Client(app.web.url)
    home = c.request("/")[2].decode()
    # a visitor is not offered a recipe menu he may not use; the part ID field takes what the server takes
    assert 'id="recipe-select"' not in home and 'data-max-length="20"' in home
    recipes = c.request("/recipes")[2].decode()  # every recipe readable by all, with its limits
    assert "rotor-a" in recipes and "0.012250 kg·m² … 0.012750 kg·m²" in recipes
    status, doc = c.json("/api/part", data={"recipe": "rotor-b"}, headers=bearer)
    assert status == 400 and "no recipe 'rotor-b'" in doc["error"]
    assert c.json("/api/part", data={"part_id": "x" * 200}, headers=bearer)[0] == 400
    assert c.json("/api/part", data={"recipe": "rotor-a"})[0] == 401  # no token, no change
    assert c.json("/api/part", data={"recipe": "rotor-a", "part_id": "SN-0042"}, headers=bearer)[0] == 202
    assert c.json("/api/measure", method="POST", headers=bearer)[0] == 202  # queued after the part: it has it
    running.wait_done(1, 60)
    state = c.json("/api/state")[1]
    assert state["recipe"] == {"name": "rotor-a", "number": 3} and state["part_id"] == "SN-0042"
    m = app.store.latest()
    assert (m.recipe, m.part_id, m.part_verdict) == ("rotor-a", "SN-0042", "OK")
    page = c.request(f"/results/{m.uuid}")[2].decode()
    assert 'verdict-OK" id="verdict"><span class="tile-word">OK' in page and "part OK" in page
    assert "SN-0042" in page and "release 1 of 1" in page
    assert m.uuid in c.request("/history?recipe=rotor-a&part=SN-0042")[2].decode()
    assert m.uuid not in c.request("/history?part=SN-0043")[2].decode()


def test_a_result_stored_without_its_plot_gets_it_drawn_once_from_its_trace(appliance_factory, tmp_path):
    off = appliance_factory(appliance_doc(tmp_path / "state"))  # the page off: no plot is drawn
    off.press()
    off.wait_done(1, 60)
    uid = off.app.store.latest().uuid
    off.stop()
    running = appliance_factory(appliance_doc(tmp_path / "state", web=ON))
    assert running.app.store.get_attachment(uid, "plot.png") is None
    status, _, png = Client(running.app.web.url).request(f"/results/{uid}/plot.png")
    assert status == 200 and png[:4] == b"\x89PNG"
    assert running.app.store.get_attachment(uid, "plot.png")[0] == png  # kept: the next view shows the same


#: what must never reach a page: a Python None, a NaN or infinity, a raw dict or list, a traceback
RAW = re.compile(r"\bNone\b|\bnan\b|\bNaN\b|\binf\b|Traceback|\{'|\['|\bTrue\b|\bFalse\b|built-in method")
#: a number in e-notation, a machine's time (ISO 8601 with its offset), a measurement's UUID (which may look like both)
E_NOTATION = re.compile(r"(?<![\w.])\d+(\.\d+)?e[+-]?\d+\b", re.I)
ISO_TIME = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d")
UUID = re.compile(r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")


def _recipes(d: Path) -> Path:
    """Three part types on the simulated rig (J 0.0125 kg·m²): one that passes on 2 releases (shown in g·cm²),
    one whose nominal is 20 % off (NOK), one whose 1σ limit no release meets (INVALID)."""
    d.mkdir()
    (d / "ok.toml").write_text('[recipe]\nname = "rotor-ok"\nnumber = 1\nnominal = 0.0125\ntolerance_percent = 2.0\n'
                               'releases = 2\ndisplay_unit = "g*cm^2"\ndisplay_decimals = 1\n')
    (d / "nok.toml").write_text('[recipe]\nname = "rotor-nok"\nnumber = 2\nnominal = 0.015\ntolerance_percent = 2.0\n')
    (d / "bad.toml").write_text('[recipe]\nname = "rotor-bad"\nnumber = 3\nnominal = 0.0125\ntolerance_percent = 2.0\n'
                                '[quality]\nmax_J_std = 1.0e-15\n')
    (d.parent / "cal-rig.toml").write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n[calibration]\n'
                                           'date = 2020-01-15\nvalid_days = 365\n')
    (d / "cal.toml").write_text('[recipe]\nname = "rotor-cal"\nnumber = 4\nnominal = 0.0125\ntolerance_percent = 2.0\n'
                                'rig = "../cal-rig.toml"\n')
    return d


def _three_release_doc(tmp_path: Path) -> dict:
    """The simulated appliance (5× real time, the web page on) with ``_recipes`` and a three-release part type,
    rotor-3, active: a part in hand between its releases."""
    recipes = _recipes(tmp_path / "recipes")
    (recipes / "three.toml").write_text('[recipe]\nname = "rotor-3"\nnumber = 5\nnominal = 0.0125\n'
                                        'tolerance_percent = 2.0\nreleases = 3\n')
    return appliance_doc(tmp_path / "state", time_scale=5.0, web=ON,
                         recipes={"directory": str(recipes), "active": "rotor-3"})


def _measure(running, c: Client, bearer: dict, recipe: str, part_id: str, count: int) -> None:
    assert c.json("/api/part", data={"recipe": recipe, "part_id": part_id}, headers=bearer)[0] == 202
    for _ in range(count):
        done = running.app.store.count()
        assert c.json("/api/measure", method="POST", headers=bearer)[0] == 202
        running.wait_done(done + 1, 60)


def test_verdict_first_pages_every_unit_written_and_no_raw_value_on_any_page(appliance_factory, tmp_path):
    running = appliance_factory(appliance_doc(tmp_path / "state", web=ON,
                                              recipes={"directory": str(_recipes(tmp_path / "recipes"))}))
    app = running.app
    bearer = {"Authorization": f"Bearer {Path(app.web.token_file).read_text().strip()}"}
    c = Client(app.web.url)
    recipes = c.request("/recipes")[2].decode()  # a count in words: "1 decimal", never "1 decimals"
    assert "g·cm², 1 decimal<" in recipes and "1 decimals" not in recipes
    _measure(running, c, bearer, "rotor-ok", "SN-1", 1)
    first = app.store.latest()
    # a part in progress: the release's own check, never a part verdict
    page = c.request(f"/results/{first.uuid}")[2].decode()
    assert "release 1 of 2" in page and "part OK" not in page and 'id="verdict"' in page
    assert "next: release 2 of 2" in c.request("/")[2].decode()
    _measure(running, c, bearer, "rotor-ok", "SN-1", 1)
    ok = app.store.latest()
    for serial in ("SN-2a", "SN-2b", "SN-2"):  # three parts: a control chart
        _measure(running, c, bearer, "rotor-nok", serial, 1)
    nok = app.store.latest()
    _measure(running, c, bearer, "rotor-bad", "SN-3", 1)
    bad = app.store.latest()
    assert (ok.part_verdict, nok.part_verdict, bad.part_verdict) == ("OK", "NOK", "INVALID")

    page = c.request(f"/results/{ok.uuid}")[2].decode()
    part = ok.payload["part"]
    # the part's value ± U in the recipe's unit (g·cm² = 1e7 kg·m²), the limits, the band
    # (in the recipe's display_decimals, U with them)
    assert f"{part['value'] * 1e7:.1f} g·cm² <span>± {part['U'] * 1e7:.1f} g·cm²" in page
    assert "part value from 2 of 2 releases, none excluded" in page and 'id="band"' in page
    assert f"{0.0125 * 0.98 * 1e7:.1f} g·cm² … {0.0125 * 1.02 * 1e7:.1f} g·cm²" in page
    assert 'class="verdict-tile verdict-OK" id="verdict"><span class="tile-word">OK' in page
    page = c.request(f"/results/{bad.uuid}")[2].decode()
    assert '<span class="tile-word">INVALID' in page and "part OK" not in page
    assert "release 1 excluded" in page and "1σ" in page
    assert '<span class="tile-word">NOK' in c.request(f"/results/{nok.uuid}")[2].decode()
    # Home: the last part's verdict as the tile, the shift's counters, the last parts, the calibration
    home = c.request("/")[2].decode()
    assert 'id="tile-verdict">INVALID' in home and "SN-3" in home
    assert [home.split(f'id="count-{v}">')[1].split("<")[0] for v in ("OK", "NOK", "INVALID")] == ["1", "3", "1"]
    assert home.count('class="chip verdict-') == 5 and 'id="calibration"' in home
    # SPC of a recipe: the chart of its 3 parts, its capability, the limits labelled with their values
    spc = c.request("/spc?recipe=rotor-nok")[2].decode()
    assert 'id="chart-points"' in spc and 'id="chart-ranges"' in spc and "I-MR" in spc and "Cpk" in spc
    # 3 parts, 2 moving ranges; drawn for a desktop and for a phone
    assert spc.count('class="point') == 2 * (3 + 2)
    assert "<title>SN-2a " in spc  # each point named by its serial (and time)
    # 3 parts: Cp and Cpk with their confidence interval, and said to be too few to decide on
    assert "95 % confidence" in spc and 'id="small-sample"' in spc and "only 3 values (fewer than 25)" in spc
    assert "USL 0.0153" in spc and "LSL 0.0147" in spc and "part value [kg·m²]" in spc
    assert c.request("/spc?recipe=no-such")[0] == 404 and c.request("/spc?chart=pie")[0] == 400
    for chart in ("Xbar-R", "Xbar-S"):  # one release a part: no subgroups; said, and I-MR drawn, not a bare 400
        status, _, body = c.request(f"/spc?recipe=rotor-nok&chart={chart}")
        assert status == 200 and 'id="spc-note"' in body.decode() and b'id="chart-points"' in body
    status, _, body = c.request("/spc?recipe=rotor-ok&chart=Xbar-S")  # one part: said, no chart
    assert status == 200 and b'id="spc-none"' in body
    assert "no calibration record" in home
    # the check standard's history on the SPC page: its control chart and each check with its E_n
    assert "no check standard measured yet" in spc
    for i, (value, passed) in enumerate(((0.01250, True), (0.01251, True), (0.01262, False))):
        app.store.record_check_standard({"name": "disc CS-1", "quantity": "J", "value": value, "U": 2e-5,
                                         "reference": 0.0125, "reference_U": 2e-5, "E_n": (value - 0.0125) / 2.8e-5,
                                         "passed": passed}, finished_at=1.7e9 + i)
    spc = c.request("/spc?recipe=rotor-nok")[2].decode()
    assert 'id="check-points"' in spc and spc.count("<td>disc CS-1</td>") == 3 and "FAILED" in spc and "4.3" in spc
    cal = c.request("/calibration")[2].decode()  # the check standard's history on the calibration page too
    assert 'id="check-points"' in cal and cal.count("<td>disc CS-1</td>") == 3
    # the calibration of the rig the active recipe measures with, and its due date, on Home
    assert c.json("/api/part", data={"recipe": "rotor-cal"}, headers=bearer)[0] == 202
    # (the main loop applies the selection: the page shows it once it did)
    wait_until(lambda: c.json("/api/state")[1]["recipe"] == {"name": "rotor-cal", "number": 4}, 10, what="rotor-cal")
    home = c.request("/")[2].decode()
    assert "DUE</b> (valid until 2021-01-14)" in home
    # an expired calibration: a banner that says what to do and whom to call; Measure refused, nothing measured
    assert 'id="blocked"' in home and "calibration expired on 2021-01-14" in home and "Call the quality" in home
    done = app.store.count()
    status, refused = c.json("/api/measure", method="POST", headers=bearer)
    assert status == 409 and "expired on 2021-01-14" in refused["error"] and app.store.count() == done
    assert c.request("/home/summary")[2].decode().startswith('<div class="summary" id="summary">')
    # the history keeps the part's verdict and each release's check apart
    hist = c.request("/history")[2].decode()
    assert "1 of 2: check OK" in hist and "on release 2 of 2" in hist
    # the flags offered in words, whole, the identifier and its meaning their tooltip
    assert re.search(r'<option value="calibration_due" title="calibration_due: [^"]+" >calibration due</option>', hist)
    # the first release, once its part is judged, points to the verdict (and is not called in progress)
    page = c.request(f"/results/{first.uuid}")[2].decode()
    assert f'<a id="part-verdict-link" href="/results/{ok.uuid}">part OK (#{ok.seq})</a>' in page
    assert "part in progress" not in page

    pages = ["/", "/history", "/spc", "/spc?recipe=rotor-ok", "/setup", "/set", "/history?recipe=rotor-bad"]
    for m in (first, ok, nok, bad):
        pages += [f"/results/{m.uuid}", f"/results/{m.uuid}/report"]
    for path in pages:
        status, _, body = c.request(path)
        text = body.decode()
        assert status == 200, (path, status, text[:300])
        found = RAW.search(re.sub(r"<script.*?</script>", "", text, flags=re.S))
        assert found is None, (path, found and text[max(0, found.start() - 120):found.end() + 60])
        # what a person reads: no number in e-notation, no raw UTC ISO time
        shown = UUID.sub("", re.sub(r"<script.*?</script>|<[^>]+>", " ", text, flags=re.S))
        found = E_NOTATION.search(shown) or ISO_TIME.search(shown)
        assert found is None, (path, found and shown[max(0, found.start() - 120):found.end() + 60])

    # the quality record: the report's PDF from the page and from `moi report`, its text read back
    from pypdf import PdfReader

    from service.cli import main

    # (made in the page's child process at a lower priority, after the plots it queued: slow on a busy machine)
    status, headers, pdf = c.request(f"/results/{bad.uuid}/report.pdf", timeout=180)
    assert status == 200 and headers["Content-Type"] == "application/pdf" and pdf[:5] == b"%PDF-"
    text = PdfReader(io.BytesIO(pdf)).pages[0].extract_text()
    assert "part INVALID" in text and "excluded: invalid" in text and "SN-3" in text
    state = str(tmp_path / "state")
    assert main(["report", ok.uuid[:8], "--state-dir", state, "--pdf", str(tmp_path / "ok.pdf")]) == 0
    text = PdfReader(str(tmp_path / "ok.pdf")).pages[0].extract_text()
    assert "part OK" in text and "g·cm²" in text and "guard band" in text and "release 2 of 2" in text
    assert text.count("used; flags: ") == 2  # each release with its flags
    report = c.request(f"/results/{ok.uuid}/report")[2].decode()
    assert f'<a href="/results/{first.uuid}">1 of 2</a>' in report and "web" in report
    assert main(["report", ok.uuid[:8], "--state-dir", state, "--pdf", str(tmp_path / "ok.png")]) == 2

    # AQDEF: the recipe's characteristic (nominal, limits, unit) and one value line per part, read back
    out = tmp_path / "rotor-ok.dfq"
    assert main(["export", "--state-dir", state, "--format", "dfq", "--recipe", "rotor-ok", "--out", str(out)]) == 0
    fields, values = {}, []
    for line in out.read_bytes().decode("cp1252").split("\r\n"):
        if line.startswith("K") and " " in line and "\x14" not in line:
            key, _, value = line.partition(" ")
            fields[key] = value
        elif line:
            values.append(line.split("\x14"))
    assert fields["K0100"] == "1" and fields["K1001"] == "rotor-ok" and fields["K2142/1"] == "g·cm²"
    places = int(fields["K2022/1"])
    assert float(fields["K2101/1"]) == pytest.approx(0.0125e7) and places >= 3
    assert float(fields["K2110/1"]) == pytest.approx(0.0125e7 * 0.98) and float(fields["K2111/1"]) == pytest.approx(0.0125e7 * 1.02)
    assert len(values) == 1 and float(values[0][0]) == pytest.approx(ok.part_value * 1e7, abs=10 ** -places)
    assert values[0][1] == "0" and values[0][2].count(".") == 2 and fields["K0014/1"] == "SN-1"
    assert main(["export", "--state-dir", state, "--format", "dfq"]) == 2  # three recipes: which one?
    status, _, web_dfq = c.request("/history/export.dfq?recipe=rotor-ok", timeout=180)  # the file of the SPC page
    assert status == 200 and web_dfq == out.read_bytes() and "/history/export.dfq?recipe=rotor-nok" in spc
    assert c.request("/history/export.dfq")[0] == 400
    # an INVALID part is in the DFQ too, with its status: marked not for SPC (attribute 255), and why
    status, _, bad_dfq = c.request("/history/export.dfq?recipe=rotor-bad", timeout=180)
    line = next(x for x in bad_dfq.decode("cp1252").split("\r\n") if "\x14" in x).split("\x14")
    assert status == 200 and line[1] == "255" and line[7].startswith("verdict INVALID: ") and float(line[0]) > 0
    # the CSV starts with a byte-order mark: Excel on Windows reads kg·m² as written
    status, _, csv_bytes = c.request("/history/export.csv", timeout=180)
    assert status == 200 and csv_bytes.startswith("\ufeff".encode()) and "kg·m²" in csv_bytes.decode("utf-8-sig")
    assert c.request("/history/export.dfq?recipe=none", timeout=180)[0] == 404


def test_a_second_measure_during_a_capture_is_refused_in_words(appliance_factory, tmp_path):
    # a capture long enough (300 s of simulated time, 12 s here) to be asked twice during it; aborted afterwards
    doc = appliance_doc(tmp_path / "state", web=ON)
    doc["sequencer"]["capture_duration"] = 300.0
    running = appliance_factory(doc)
    app = running.app
    bearer = {"Authorization": f"Bearer {Path(app.web.token_file).read_text().strip()}"}
    c = Client(app.web.url)
    assert c.json("/api/measure", method="POST", headers=bearer)[0] == 202
    running.wait_event(lambda e: e.state.value == "CAPTURING", 30, what="the capture")
    status, doc = c.json("/api/measure", method="POST", headers=bearer)
    assert status == 409 and "already running" in doc["error"] and "IDLE" in doc["error"]
    assert c.json("/api/abort", method="POST", headers=bearer)[0] == 202
    running.wait_done(1, 30)
    assert app.store.latest(None).status == "aborted"


def test_operators_by_name_roles_and_who_started_a_result(appliance_factory, tmp_path, monkeypatch, capsys):
    from service.cli import main
    from service.publish.web.auth import allowed, check_password

    users = tmp_path / "users.toml"
    for name, role, pw in (("olga", "operator", "olga-password-1"), ("quinn", "quality", "quinn-password-2")):
        monkeypatch.setattr("sys.stdin", io.StringIO(pw + "\n"))
        assert main(["user", "add", name, "--role", role, "--users-file", str(users), "--password-stdin"]) == 0
    monkeypatch.setattr("sys.stdin", io.StringIO("short\n"))
    assert main(["user", "add", "x", "--users-file", str(users), "--password-stdin"]) == 2
    text = users.read_text()
    assert "olga-password-1" not in text and stat.S_IMODE(os.stat(users).st_mode) == 0o600  # only hashes
    assert check_password("olga-password-1", text.split('password = "')[1].split('"')[0])
    assert not allowed("operator", "acknowledge") and allowed("quality", "acknowledge") and allowed("admin", "recipe")

    d = tmp_path / "recipes"
    d.mkdir()
    (d / "a.toml").write_text('[recipe]\nname = "rotor-a"\nnumber = 3\nnominal = 0.0125\ntolerance_percent = 2.0\n')
    running = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True, "users_file": str(users)},
                                              recipes={"directory": str(d)}))
    app = running.app

    def login(name: str, pw: str) -> tuple[Client, str]:
        c = Client(app.web.url)
        status, _, page = c.request("/login", {"user": name, "token": pw, "csrf": c.csrf()})
        assert status == 200 and f"{name} (" in page.decode()
        return c, page.decode().split('name="csrf-token" content="')[1].split('"')[0]

    c = Client(app.web.url)
    status, _, body = c.request("/login", {"user": "olga", "token": "wrong-password", "csrf": c.csrf()})
    assert status == 401 and b"wrong user name or password" in body
    olga, csrf = login("olga", "olga-password-1")
    status, doc = olga.json("/api/part", data={"recipe": "rotor-a"}, headers={"X-CSRF-Token": csrf})
    assert status == 403 and "olga (operator) may not change the recipe" in doc["error"]
    assert olga.json("/api/part", data={"part_id": "SN-7"}, headers={"X-CSRF-Token": csrf})[0] == 202
    quinn, qcsrf = login("quinn", "quinn-password-2")
    assert quinn.json("/api/part", data={"recipe": "rotor-a"}, headers={"X-CSRF-Token": qcsrf})[0] == 202
    assert olga.json("/api/measure", method="POST", headers={"X-CSRF-Token": csrf})[0] == 202
    running.wait_done(1, 60)
    m = app.store.latest()
    assert m.trigger == "web:olga" and m.part_verdict == "OK"
    assert "web:olga" in olga.request(f"/results/{m.uuid}/report")[2].decode()
    # a fault is acknowledged by a quality engineer, not by an operator
    app.sequencer.fault("encoder fault: test cable pulled")
    running.wait_event(lambda e: e.state.value == "FAULT", 10, what="FAULT")
    status, doc = olga.json("/api/abort", method="POST", headers={"X-CSRF-Token": csrf})
    assert status == 403 and "may not acknowledge a fault" in doc["error"]
    assert quinn.json("/api/abort", method="POST", headers={"X-CSRF-Token": qcsrf})[0] == 202
    running.wait_event(lambda e: e.state.value == "IDLE" and e.previous.value == "ABORTED", 10, what="acknowledged")

    # a recipe edited by a quality engineer: checked as a recipe file is, written back, shown, and audited
    assert 'id="edit-3"' not in olga.request("/recipes")[2].decode()  # not offered to an operator
    status, _, _ = olga.request("/recipes", {"recipe": "rotor-a", "nominal": "0.013", "csrf": csrf})
    assert status == 403 and "nominal = 0.0125" in (d / "a.toml").read_text()
    page = quinn.request("/recipes")[2].decode()
    assert 'id="edit-3"' in page and 'name="tolerance_percent"' in page and 'value="0.0125"' in page
    status, _, answer = quinn.request("/recipes", {"recipe": "rotor-a", "nominal": "0.0125",
                                                   "tolerance_percent": "200", "releases": "2", "csrf": qcsrf})
    assert status == 400 and 'id="recipe-error"' in answer.decode() and "tolerance" in answer.decode()
    assert 'value="200"' in answer.decode() and "releases" not in (d / "a.toml").read_text()  # kept, not written
    status, _, answer = quinn.request("/recipes", {"recipe": "rotor-a", "nominal": "nan", "csrf": qcsrf})
    assert status == 400 and "expected a finite number, got &#39;nan&#39;" in answer.decode()
    status, _, answer = quinn.request("/recipes", {"recipe": "rotor-a", "nominal": "0.013", "releases": "2",
                                                   "tolerance_percent": "2.0", "display_decimals": "",
                                                   "csrf": qcsrf})
    text = (d / "a.toml").read_text()
    assert status == 200 and "nominal = 0.013\n" in text and "releases = 2" in text
    assert "0.012740 kg·m² … 0.013260 kg·m²" in answer.decode() and app.parts.book.find("rotor-a").releases == 2
    audit = (tmp_path / "state" / "recipe-audit.log").read_text().splitlines()
    assert len(audit) == 1 and "web:quinn\trotor-a\ta.toml\tnominal: 0.0125 → 0.013; releases: – → 2" in audit[0]

    # the users, for an admin only: add one (a short password refused on the page, the name kept), remove one
    assert quinn.request("/users")[0] == 403
    admin = Client(app.web.url)
    admin.request("/login", {"token": Path(app.web.token_file).read_text().strip(), "csrf": admin.csrf()})
    page = admin.request("/users")[2].decode()
    acsrf = page.split('name="csrf-token" content="')[1].split('"')[0]
    assert "<td>olga</td><td>operator</td>" in page and 'id="lockout"' in page and "Wrong logins" in page
    # olga's one wrong password is counted against her name; disabled, she is shown so and cannot log in
    assert page.split('id="user-olga"')[1].split('class="wrong-logins">')[1].startswith("1<")
    assert admin.request("/users", {"action": "disable", "name": "olga", "csrf": acsrf})[0] == 200
    assert "disabled = true" in users.read_text() and olga.request("/users")[0] == 403
    assert olga.json("/api/part", data={"part_id": "SN-8"}, headers={"X-CSRF-Token": csrf})[0] == 401  # session ended
    c = Client(app.web.url)
    status, _, body = c.request("/login", {"user": "olga", "token": "olga-password-1", "csrf": c.csrf()})
    assert status == 403 and "the user olga is disabled" in body.decode()
    page = admin.request("/users")[2].decode()
    assert page.split('id="user-olga"')[1].split('class="login-state">')[1].startswith("disabled<")
    status, _, answer = admin.request("/users", {"action": "add", "name": "ada", "role": "quality",
                                                 "password": "short", "csrf": acsrf})
    assert status == 400 and "a password needs 10" in answer.decode() and 'value="ada"' in answer.decode()
    status, _, answer = admin.request("/users", {"action": "add", "name": "ada", "role": "quality",
                                                 "password": "ada-password-3", "csrf": acsrf})
    assert status == 200 and "<td>ada</td><td>quality</td>" in answer.decode()  # (after the redirect)
    assert "ada" in users.read_text() and "ada-password-3" not in users.read_text()
    login("ada", "ada-password-3")
    assert admin.request("/users", {"action": "remove", "name": "olga", "confirm": "olga", "csrf": acsrf})[0] == 200
    c = Client(app.web.url)
    assert c.request("/login", {"user": "olga", "token": "olga-password-1", "csrf": c.csrf()})[0] == 401


def test_wrong_passwords_lock_a_name_out_from_their_address_only_for_a_while_and_an_admin_lifts_it():
    """LOCKOUT_WRONG wrong passwords for a name from one address within the window lock that name out from that
    address (its right password refused there unchecked); the same name logs in from any other address, so
    nobody on the network can lock a user (the admin included) out alone. Time is moved by hand."""
    from service.publish.web.auth import LOCKOUT_TIME, LOCKOUT_WINDOW, LOCKOUT_WRONG, Guard, User, hash_password

    now = [0.0]
    olga = User("olga", "operator", hash_password("olga-password-1"))
    root = User("root", "admin", hash_password("root-password-1"))
    guard = Guard("t" * 24, clock=lambda: now[0], users={"olga": olga, "root": root})
    guesser, desk = "192.0.2.66", "192.0.2.10"
    # wrong passwords spread wider than the window lock nobody out
    for _ in range(LOCKOUT_WRONG):
        assert guard.login("wrong", "olga", guesser) is None
        now[0] += LOCKOUT_WINDOW / (LOCKOUT_WRONG - 1)
    assert guard.throttled("olga", guesser) == 0 and guard.login("olga-password-1", "olga", guesser) is not None
    now[0] += LOCKOUT_WINDOW
    for name in ("olga", "root"):  # within the window: locked out, from the guesser's address only
        for _ in range(LOCKOUT_WRONG):
            assert guard.login("wrong", name, guesser) is None
        assert guard.throttled(name, guesser) == LOCKOUT_TIME
        assert guard.login(f"{name}-password-1", name, guesser) is None
        assert guard.login(f"{name}-password-1", name, desk) is not None  # at their own desk: in at once
    assert guard.throttled("root", desk) == 0 and guard.locked_for("olga") == LOCKOUT_TIME
    assert guard.wrong_logins["olga"] == 2 * LOCKOUT_WRONG  # the refused right password is not counted
    now[0] += LOCKOUT_TIME / 2
    guard.unlock("olga")  # the admin's "enable"
    assert guard.locked_for("olga") == 0 and guard.login("olga-password-1", "olga", guesser) is not None
    assert guard.throttled("root", guesser) > 0  # another user's lockout stays
    for _ in range(LOCKOUT_WRONG):
        guard.login("wrong", "olga", guesser)
    now[0] += LOCKOUT_TIME  # and the lockout ends by itself
    assert guard.login("olga-password-1", "olga", guesser) is not None
    assert guard.login("t" * 24, None, guesser) is not None  # the token is never locked out


def test_an_address_guessing_through_the_names_is_locked_out_of_every_name_but_not_of_the_token():
    """SOURCE_WRONG wrong passwords from one address, a few per name (names that are no user's count the same:
    they are not told apart), lock every named login from that address out; other addresses are untouched."""
    from service.publish.web.auth import LOCKOUT_TIME, LOCKOUT_WRONG, SOURCE_WRONG, Guard, User, hash_password

    now = [0.0]
    root = User("root", "admin", hash_password("root-password-1"))
    guard = Guard("t" * 24, clock=lambda: now[0], users={"root": root})
    names = [f"name-{i}" for i in range(SOURCE_WRONG)]
    for i in range(SOURCE_WRONG):
        assert guard.throttled("root", "192.0.2.66") == 0
        guard.login("wrong", names[i // (LOCKOUT_WRONG - 1)], "192.0.2.66")
    assert guard.throttled("root", "192.0.2.66") == LOCKOUT_TIME  # never guessed, locked out from there
    assert guard.login("root-password-1", "root", "192.0.2.66") is None
    assert guard.login("root-password-1", "root", "192.0.2.10") is not None
    assert guard.login("t" * 24, None, "192.0.2.66") is not None
    assert guard.wrong_logins == {}  # only users' names are counted for the page


def test_a_locked_out_login_is_told_it_is_paused_not_that_its_password_is_wrong(appliance_factory, tmp_path,
                                                                                 monkeypatch):
    """Over HTTP: after LOCKOUT_WRONG wrong passwords the right one is answered 429 with Retry-After and words
    saying the logins are paused (the password was not tried); the admin's page lists the lockout with its
    address; the token still logs in from that address."""
    from service.publish.web import auth
    from service.publish.web.auth import LOCKOUT_WRONG, User, hash_password, save_users

    monkeypatch.setattr(auth, "GUESS_DELAY", 0.01)
    users = tmp_path / "users.toml"
    save_users(users, {"root": User("root", "admin", hash_password("root-password-1"))})
    app = appliance_factory(appliance_doc(tmp_path / "state", web={"enabled": True, "users_file": str(users)})).app
    c = Client(app.web.url)
    for _ in range(LOCKOUT_WRONG):
        status, _, body = c.request("/login", {"user": "root", "token": "wrong-password", "csrf": c.csrf()})
        assert status == 401 and "wrong user name or password" in body.decode()
    status, headers, body = c.request("/login", {"user": "root", "token": "root-password-1", "csrf": c.csrf()})
    page = body.decode()
    assert status == 429 and int(headers["Retry-After"]) > 0, (status, headers)
    assert "too many wrong passwords" in page and re.search(r"\(127\.0\.0\.1\) are paused until [-0-9]+ [0-9:]+ \(1[0-5] more min\)", page)
    assert "it was not tried" in page and "wrong user name or password" not in page
    status, doc = c.json("/login", data=urllib.parse.urlencode({"user": "root", "token": "root-password-1",
                                                                "csrf": c.csrf()}).encode())
    assert status == 429 and "paused" in doc["error"]
    assert login_from("127.0.0.2", app.web.bound_port, user="root", token="root-password-1").status == 303  # in
    token = Path(app.web.token_file).read_text().strip()
    status, _, body = c.request("/login", {"token": token, "csrf": c.csrf()})
    assert status == 200 and 'id="lockouts"' in c.request("/users")[2].decode()
    row = c.request("/users")[2].decode().split('id="lockouts"')[1]
    assert re.search(r"<td>root</td><td>127\.0\.0\.1</td><td>1[0-5]</td>", row), row  # min left

