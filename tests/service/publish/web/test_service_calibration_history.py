"""The rig's calibration history: each `moi calibrate --out` appends one line beside the rig file, and the web
page's Calibration lists them (the daemon's aiohttp server on loopback), newest first, in the page's local time
and without e-notation; a damaged line is said, not a traceback."""

from __future__ import annotations

import html
import json
import re
import shutil
import threading
import tracemalloc

from service.cli import main
from service.sources.calibrations import history_path, read_history
from tests.service.conftest import REPO, appliance_doc
from tests.service.publish.web.test_service_web import E_NOTATION, ISO_TIME, Client


def _calibrate(tmp_path, date: str, by: str) -> None:
    assert main(["calibrate", str(tmp_path / "calibration.toml"), "--rig", str(tmp_path / "rig.toml"),
                 "--out", str(tmp_path / "rig.toml"), "--date", date, "--by", by]) == 0


def test_two_calibrations_give_two_history_rows_and_a_damaged_line_is_said(tmp_path, appliance_factory, capsys):
    shutil.copy(REPO / "examples" / "torsion_rig.toml", tmp_path / "rig.toml")
    shutil.copy(REPO / "examples" / "calibration.toml", tmp_path / "calibration.toml")
    _calibrate(tmp_path, "2026-01-10", "A. Meyer")
    _calibrate(tmp_path, "2026-06-01", "B. Kraus")
    assert "calibration appended to" in capsys.readouterr().out

    # the history beside the rig file: one line a calibration, read newest first, with who ran it and the certificate
    history = read_history(tmp_path / "rig.toml", None)
    assert history.path == tmp_path / "rig.calibrations.jsonl" and history.damaged == [] and history.older is None
    assert [(e["date"], e["by"], e["valid_until"]) for e in history.entries] == [
        ("2026-06-01", "B. Kraus", "2027-06-01"), ("2026-01-10", "A. Meyer", "2027-01-10")]
    first = history.entries[1]
    assert first["rig_file"] == str((tmp_path / "rig.toml").resolve()) and first["stiffness_std"] > 0
    assert {"name": "disc 5 g·m²", "certificate": "LAB-2025-0412"}.items() <= first["references"][1].items()

    running = appliance_factory(appliance_doc(tmp_path / "state", device={"rig": str(tmp_path / "rig.toml")},
                                              web={"enabled": True}))
    c = Client(running.app.web.url)
    status, _, body = c.request("/calibration")
    page = body.decode()
    assert status == 200
    rows = re.findall(r'<tr class="cal-row">(.*?)</tr>', page)
    assert len(rows) == 2 and "2026-06-01" in rows[0] and "2026-01-10" in rows[1]  # newest first
    assert "B. Kraus" in rows[0] and "LAB-2025-0412" in rows[0] and "N·m/rad" in rows[0] and "kg·m²" in rows[0]
    shown = "".join(re.sub(r"<[^>]+>", " ", r) for r in rows)
    assert E_NOTATION.search(shown) is None and ISO_TIME.search(shown) is None, shown  # local time, no exponents

    # a line cut short (a power loss while writing) and one that is not a calibration: said, the others listed
    path = history_path(tmp_path / "rig.toml")
    cut, short = path.stat().st_size, '{"date": "2026-07-0\n'
    with open(path, "a", encoding="utf-8") as f:
        f.write(short + json.dumps({"date": "2026-08-01"}) + "\n")
    status, _, body = c.request("/calibration")
    page = body.decode()
    assert status == 200 and "Traceback" not in page
    assert len(re.findall(r'<tr class="cal-row">', page)) == 2
    assert f"the line at byte {cut} of rig.calibrations.jsonl is damaged (not JSON" in page
    assert (f"the line at byte {cut + len(short)} of rig.calibrations.jsonl is damaged (no recorded_at, stiffness)"
            in page)


def _line(i: int) -> str:
    return json.dumps({"date": "2026-01-10", "recorded_at": f"2026-01-10T00:{i // 60:02d}:{i % 60:02d}Z",
                       "stiffness": 0.365 + i * 1e-6, "by": f"tech {i}", "references": [{"name": "disc"}]}) + "\n"


def _huge_history(rig, calibrations: int, size: int) -> None:
    """A history of ``size`` bytes: one line too long to be a calibration (a hole of the file, read as zeros),
    then ``calibrations`` calibrations, oldest first."""
    with open(history_path(rig), "wb") as f:
        f.truncate(size - 1)
        f.seek(size - 1)
        f.write(b"\n" + "".join(_line(i) for i in range(calibrations)).encode())


def test_a_huge_history_is_read_a_page_at_a_time_from_its_end(tmp_path):
    rig = tmp_path / "rig.toml"
    _huge_history(rig, 45, 64 * 2**20)
    tracemalloc.start()
    try:
        page = read_history(rig, 20)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 * 2**20, peak  # the page's lines and a block, not the file's 64 MiB
    assert [e["by"] for e in page.entries] == [f"tech {i}" for i in range(44, 24, -1)] and page.damaged == []
    # the older pages, each read before the oldest line shown, down to the first line
    seen, before, damaged = [e["by"] for e in page.entries], page.older, []
    while before is not None:
        page = read_history(rig, 20, before)
        seen += [e["by"] for e in page.entries]
        damaged += page.damaged
        before = page.older
    assert seen == [f"tech {i}" for i in range(44, -1, -1)]
    assert damaged == ["the line at byte 0 of rig.calibrations.jsonl is damaged (longer than 64 KiB); left out"]


def test_the_page_lists_the_history_a_page_at_a_time_and_reads_it_off_the_web_loop(tmp_path, appliance_factory,
                                                                                   monkeypatch):
    shutil.copy(REPO / "examples" / "torsion_rig.toml", tmp_path / "rig.toml")
    _huge_history(tmp_path / "rig.toml", 12, 64 * 2**20)
    running = appliance_factory(appliance_doc(tmp_path / "state", device={"rig": str(tmp_path / "rig.toml")},
                                              web={"enabled": True, "page_size": 5}))
    c = Client(running.app.web.url)
    pages, path = [], "/calibration"
    while path:
        status, _, body = c.request(path)
        assert status == 200
        page = body.decode()
        pages.append(re.findall(r'<tr class="cal-row">.*?<td>(tech \d+)</td>', page))
        older = re.search(r'<a class="older" href="([^"#]+)', page)
        path = html.unescape(older.group(1)) if older else ""
        assert len(pages) <= 5
    assert pages == [[f"tech {i}" for i in range(j, max(j - 5, -1), -1)] for j in (11, 6, 1)]
    assert "the line at byte 0 of rig.calibrations.jsonl is damaged (longer than 64 KiB)" in page
    assert c.request("/calibration?rig=0&before=x")[0] == 400

    # while one request reads a history, the page answers another: the file is read off the web loop
    from service.publish.web import calibration

    reading, release = threading.Event(), threading.Event()

    def slow_read(*args, **kw):
        reading.set()
        assert release.wait(30)
        return read_history(*args, **kw)

    monkeypatch.setattr(calibration, "read_history", slow_read)
    slow = threading.Thread(target=c.request, args=("/calibration",))
    slow.start()
    try:
        assert reading.wait(30)
        assert Client(running.app.web.url).request("/", timeout=10)[0] == 200
    finally:
        release.set()
        slow.join(30)


def test_the_page_shows_the_rigs_reproducibility_pooled_from_its_check_standards(tmp_path, appliance_factory):
    shutil.copy(REPO / "examples" / "torsion_rig.toml", tmp_path / "rig.toml")
    shutil.copy(REPO / "examples" / "calibration.toml", tmp_path / "calibration.toml")
    _calibrate(tmp_path, "2026-06-01", "A. Meyer")
    running = appliance_factory(appliance_doc(tmp_path / "state", device={"rig": str(tmp_path / "rig.toml")},
                                              web={"enabled": True}))
    c = Client(running.app.web.url)
    status, _, body = c.request("/calibration")
    repro = re.search(r'<dd class="cal-repro">(.*?)</dd>', body.decode(), re.S)
    assert status == 200 and repro is not None and "not known: no object released twice" in repro.group(1)
    # the example calibration releases each reference once: one release's u counts the documented default
    counted = re.search(r'<dd class="cal-repro-counted">(.*?)</dd>', body.decode(), re.S)
    assert counted is not None and "the documented default ± 0.1 % of ω_n" in html.unescape(counted.group(1))
    assert 'class="cal-repro-rig"' not in body.decode()
    store = running.app.store
    # one check standard three times after the calibration (J ± 0.16 %: ω_n ± 0.08 %), one the day before it
    day = 1_780_272_000.0  # 2026-06-01 00:00 UTC
    for at, v in ((day - 3600, 0.0200), (day + 10, 0.01250), (day + 20, 0.01252), (day + 30, 0.01248)):
        store.record_check_standard({"name": "disc", "quantity": "J_object", "value": v, "U": 2e-5,
                                     "reference": 0.0125, "reference_U": 2e-5, "E_n": 0.1, "passed": True},
                                    finished_at=at)
    status, _, body = c.request("/calibration")
    repro = re.search(r'<dd class="cal-repro">(.*?)</dd>', body.decode(), re.S)
    assert status == 200 and repro is not None
    shown = html.unescape(re.sub(r"<[^>]+>", "", repro.group(1)))
    assert "± 0.08 % of ω_n (± 0.16 % of J)" in shown and "3 repeat releases of 1 object since" in shown, shown
    assert "ν = 2" in shown
    counted = re.search(r'<dd class="cal-repro-counted">(.*?)</dd>', body.decode(), re.S)
    assert counted is not None and counted.group(1) == "the history's figure"


def test_the_page_shows_the_figure_the_calibration_keeps_and_that_one_release_counts_it(tmp_path, appliance_factory):
    shutil.copy(REPO / "examples" / "torsion_rig.toml", tmp_path / "rig.toml")
    shutil.copy(REPO / "examples" / "calibration.toml", tmp_path / "calibration.toml")
    _calibrate(tmp_path, "2026-06-01", "A. Meyer")
    rig = tmp_path / "rig.toml"
    text = rig.read_text(encoding="utf-8")
    assert "[calibration]\n" in text
    rig.write_text(text.replace("[calibration]\n", "[calibration]\nreproducibility = 0.0005\nreproducibility_dof = 3\n"),
                   encoding="utf-8")
    running = appliance_factory(appliance_doc(tmp_path / "state", device={"rig": str(rig)}, web={"enabled": True}))
    body = Client(running.app.web.url).request("/calibration")[2].decode()
    kept = re.search(r'<dd class="cal-repro-rig">(.*?)</dd>', body, re.S)
    counted = re.search(r'<dd class="cal-repro-counted">(.*?)</dd>', body, re.S)
    assert kept is not None and "± 0.05 % of ω_n (± 0.1 % of J)" in html.unescape(kept.group(1))
    assert "ν = 3" in kept.group(1)
    assert counted is not None and counted.group(1) == "the calibration's figure"
