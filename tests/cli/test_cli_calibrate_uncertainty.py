"""`moi calibrate` with the references' stated uncertainties: a certificate's σ moves k's σ, the rig
written gets k, I0 and their covariance, and a bad σ is one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.cli import main
from service.sources.files import read_rig

REPO = Path(__file__).resolve().parents[2]
CAL = (REPO / "examples" / "calibration.toml").read_text()
RIG = str(REPO / "examples" / "torsion_rig.toml")


def calibrate(tmp_path: Path, text: str, capsys, *extra: str) -> dict:
    path = tmp_path / "cal.toml"
    path.write_text(text)
    assert main(["calibrate", str(path), "--rig", RIG, "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)


def test_a_references_certificate_moves_ks_uncertainty_and_the_rig_gets_the_covariance(tmp_path, capsys):
    base = calibrate(tmp_path, CAL, capsys, "--out", str(tmp_path / "rig.toml"))
    assert base["basis"] == "stated" and base["stiffness_std"] / base["stiffness"] > 1e-4
    wider = calibrate(tmp_path, CAL.replace("added_inertia_std = 1e-5", "added_inertia_std = 1e-4"), capsys)
    assert wider["stiffness_std"] > 1.1 * base["stiffness_std"]
    rig = read_rig(str(tmp_path / "rig.toml"))
    assert rig.stiffness_tare_covariance == pytest.approx(base["stiffness_tare_covariance"])
    assert rig.stiffness_tare_covariance is not None and rig.stiffness_std and rig.tare_inertia_std
    assert rig.stiffness_tare_covariance / (rig.stiffness_std * rig.tare_inertia_std) == pytest.approx(
        base["correlation"])


def test_a_negative_certificate_sigma_is_one_line(tmp_path, capsys):
    path = tmp_path / "cal.toml"
    path.write_text(CAL.replace("added_inertia_std = 1e-5", "added_inertia_std = -1e-5"))
    assert main(["calibrate", str(path), "--rig", RIG]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "added_inertia_std must be a standard uncertainty >= 0" in err[0]
