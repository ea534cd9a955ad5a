"""Names that reach a terminal, a file or a page through `moi calibrate` and `moi check-standard` (who
calibrated, the references' names and certificates, the artifact's name, a rig file's or a history's edited by
hand) follow the names rule: a control character or an escape sequence is refused with a one-line message that
shows it escaped, and never reaches the terminal raw."""

from __future__ import annotations

import json
import shutil

import pytest

from service.cli import main
from service.sources.calibrations import history_path, read_history
from tests.service.conftest import REPO

#: an escape sequence that retitles the terminal window, a bell, a line break, a right-to-left override
HOSTILE = ("\x1b]0;owned\x07", "A. Meyer\x1b[2J", "line\nbreak", "tab\there", "evil\u202etxt.exe")


@pytest.fixture
def bench(tmp_path):
    shutil.copy(REPO / "examples" / "torsion_rig.toml", tmp_path / "rig.toml")
    shutil.copy(REPO / "examples" / "calibration.toml", tmp_path / "calibration.toml")
    return tmp_path


def _calibrate(bench, *extra: str) -> int:
    return main(["calibrate", str(bench / "calibration.toml"), "--rig", str(bench / "rig.toml"),
                 "--out", str(bench / "rig.toml"), *extra])


def _refused(capsys, code: int, *expected: str) -> str:
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and err.count("\n") == 1, (code, out, err)
    assert all(e in err for e in expected), err
    assert not any(c in err[:-1] for c in "\x1b\x07\t\u202e"), err  # escaped in the message, never raw
    return err


@pytest.mark.parametrize("name", HOSTILE)
def test_calibrate_by_refuses_control_characters(bench, capsys, name):
    _refused(capsys, _calibrate(bench, "--by", name), "--by: the name of who calibrated must be printable")
    assert not history_path(bench / "rig.toml").exists()  # nothing written


def test_calibrate_refuses_a_login_name_with_control_characters(bench, capsys, monkeypatch):
    monkeypatch.setenv("LOGNAME", "\x1b[31mroot")
    _refused(capsys, _calibrate(bench), "the login name is not a good name", "give --by NAME")
    assert _calibrate(bench, "--by", "B. Kraus") == 0  # a good --by is used instead of the login name


@pytest.mark.parametrize("key", ["name", "certificate"])
@pytest.mark.parametrize("name", HOSTILE)
def test_calibrate_refuses_reference_names_and_certificates_with_control_characters(bench, capsys, key, name):
    text = (bench / "calibration.toml").read_text()
    old = 'name = "disc 5 g·m²"' if key == "name" else 'certificate = "LAB-2025-0412"'
    (bench / "calibration.toml").write_text(text.replace(old, f"{key} = {json.dumps(name)}"))
    what = "reference name" if key == "name" else "certificate"
    _refused(capsys, _calibrate(bench, "--by", "A. Meyer"), f"{what} must be printable characters")


def test_a_rig_file_whose_calibration_names_hold_an_escape_is_refused(bench, capsys):
    assert _calibrate(bench, "--by", "A. Meyer") == 0
    capsys.readouterr()
    rig = bench / "rig.toml"
    rig.write_text(rig.read_text().replace("LAB-2025-0412", "LAB\\u001b[2J"))
    _refused(capsys, main(["calibrate", str(bench / "calibration.toml"), "--rig", str(rig)]),
             "[calibration] references: certificate must be printable characters")


def test_a_history_line_with_an_escape_in_a_name_is_said_damaged_not_shown(bench):
    assert _calibrate(bench, "--by", "A. Meyer") == 0
    path = history_path(bench / "rig.toml")
    good = json.loads(path.read_text())
    with open(path, "a", encoding="utf-8") as f:
        for doc in (good | {"by": "\x1b]0;owned\x07"},
                    good | {"references": [{"name": "disc\x1b[2J"}]},
                    good | {"references": [{"name": "disc", "certificate": "C\u202e1"}]}):
            f.write(json.dumps(doc) + "\n")
    history = read_history(bench / "rig.toml", None)
    assert [e["by"] for e in history.entries] == ["A. Meyer"]
    assert [d.split("(", 1)[1].split(" must")[0] for d in history.damaged] == [
        "certificate", "reference name", "the name of who calibrated"]


@pytest.mark.parametrize("name", HOSTILE)
def test_check_standard_refuses_an_artifact_name_with_control_characters(tmp_path, capsys, name):
    code = main(["check-standard", "--history", "--name", name, "--state-dir", str(tmp_path)])
    _refused(capsys, code, "--name: check standard name must be printable characters")


def test_a_stored_check_standard_name_with_an_escape_is_shown_escaped(tmp_path, capsys):
    """A name stored before the rule held (or written by another program) never reaches the terminal raw."""
    from service.persistence.store import Store

    with Store(tmp_path) as store:
        store.record_check_standard({"name": "disc\x1b]0;owned\x07", "quantity": "J_object", "value": 0.0125,
                                     "U": 2e-5, "reference": 0.0125, "reference_U": 2e-5, "E_n": 0.1,
                                     "passed": True, "deviation": 1e-7}, finished_at=1.8e9)
    assert main(["check-standard", "--history", "--state-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\x07" not in out and "'disc\\x1b]0;own" in out
