"""The rig's calibration history: each `moi calibrate --out` appends one line beside the rig file, and the web
page's Calibration lists them (the daemon's aiohttp server on loopback), newest first, in the page's local time
and without e-notation; a damaged line is said, not a traceback."""

from __future__ import annotations

import json
import re
import shutil

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

    # the history beside the rig file: one line a calibration, oldest first, with who ran it and the certificate
    history = read_history(tmp_path / "rig.toml")
    assert history.path == tmp_path / "rig.calibrations.jsonl" and history.damaged == []
    assert [(e["date"], e["by"], e["valid_until"]) for e in history.entries] == [
        ("2026-01-10", "A. Meyer", "2027-01-10"), ("2026-06-01", "B. Kraus", "2027-06-01")]
    first = history.entries[0]
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
    with open(history_path(tmp_path / "rig.toml"), "a", encoding="utf-8") as f:
        f.write('{"date": "2026-07-0\n' + json.dumps({"date": "2026-08-01"}) + "\n")
    status, _, body = c.request("/calibration")
    page = body.decode()
    assert status == 200 and "Traceback" not in page
    assert len(re.findall(r'<tr class="cal-row">', page)) == 2
    assert "line 3 of rig.calibrations.jsonl is damaged (not JSON" in page
    assert "line 4 of rig.calibrations.jsonl is damaged (no recorded_at, stiffness)" in page
