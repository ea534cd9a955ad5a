"""`moi check-standard`: a reference artifact of certified J ± U measured, its E_n stored, its history
charted, and the appliance's calibration due while the newest check has failed."""

from __future__ import annotations

import datetime as dt
import json
import time
from pathlib import Path

import numpy as np
import pytest

from measurement import Pendulum, simulate_trace
from measurement.result import SCHEMA_VERSION
from measurement.rig import CalibrationRecord
from service.cli import main
from service.parts.calibration import calibration_state
from service.persistence.store import Store
from service.settings.defaults import DEMO_RIG
from service.sources.files import read_rig

ARTIFACT = 0.0125  # kg·m², the artifact's own inertia (J_object)


@pytest.fixture(scope="module")
def swing(tmp_path_factory) -> Path:
    rig = DEMO_RIG
    tr = simulate_trace(Pendulum(rig, ARTIFACT + (rig.tare_inertia or 0.0), {"viscous": {"c": 2e-4}}), theta0=0.3,
                        duration=12.0, rate=100.0, noise_std=1e-4, seed=5)
    path = tmp_path_factory.mktemp("check") / "artifact.csv"
    path.write_text("t,angle\n" + "\n".join(f"{float(t)!r},{float(a)!r}" for t, a in zip(tr.t, tr.angle)) + "\n")
    return path


@pytest.fixture(scope="module")
def rig_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rig") / "rig.toml"
    path.write_text((Path(__file__).resolve().parents[2] / "examples" / "torsion_rig.toml").read_text())
    return path


def test_check_standard_passes_fails_is_stored_and_charted(swing, rig_file, tmp_path, capsys):
    state = tmp_path / "state"
    args = ["check-standard", str(swing), "--rig", str(rig_file), "--state-dir", str(state), "--json"]
    assert main(args + ["--reference", str(ARTIFACT), "--reference-U", "2e-5"]) == 0
    ok = json.loads(capsys.readouterr().out)
    assert ok["passed"] and ok["E_n"] <= 1 and ok["stored"]
    assert ok["E_n"] == pytest.approx(abs(ok["deviation"]) / np.hypot(ok["U"], 2e-5))
    # a certificate 1 % off: the budget cannot cover it, exit 3 (not bad input, not a bug)
    assert main(args + ["--reference", str(ARTIFACT * 1.01), "--reference-U", "2e-5"]) == 3
    bad = json.loads(capsys.readouterr().out)
    assert not bad["passed"] and bad["E_n"] > 1
    assert main(["check-standard", "--history", "--state-dir", str(state), "--plot", str(tmp_path / "cs.png")]) == 0
    out = capsys.readouterr().out
    assert out.count("  pass\n") == 1 and out.count("  FAIL\n") == 1 and "I-MR chart" in out
    assert (tmp_path / "cs.png").read_bytes()[:4] == b"\x89PNG"
    # the appliance: its results are calibration_due while the newest check since the calibration failed
    with Store(state) as store:
        checks = store.check_standards(limit=1)
        now = time.time()
        state_now = calibration_state(DEMO_RIG, checks, now)
        assert state_now is not None and state_now["due"] and state_now["check_standard"]["passed"] is False
        recalibrated = DEMO_RIG.__class__(**{**DEMO_RIG.__dict__, "calibration": CalibrationRecord(
            dt.datetime.now(dt.UTC).date() + dt.timedelta(days=1), 365)})
        state_later = calibration_state(recalibrated, checks, now)
        assert state_later is not None and not state_later["due"]


@pytest.mark.parametrize(("extra", "words"), [
    (["--reference", "0.0125", "--reference-U=-1e-5"], "must be >= 0"),
    (["--reference", "0.0125"], "give SOURCE, --rig, --reference"),
])
def test_bad_check_standard_input_is_one_line(swing, rig_file, capsys, extra, words):
    assert main(["check-standard", str(swing), "--rig", str(rig_file), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0]


def test_identify_json_carries_the_expanded_uncertainty_and_its_budget(swing, rig_file, capsys):
    assert main(["identify", str(swing), "--rig", str(rig_file), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["schema"] == SCHEMA_VERSION and d["coverage_factor"] == 2.0
    assert d["J_U"] == pytest.approx(2 * d["J_u"]) and d["J_object_U"] < d["J_U"]  # k and I0 correlated
    lines = {ln["symbol"]: ln for ln in d["uncertainty_budget"]["J_object"]["lines"]}
    assert {"omega_n_fit", "clock", "k", "I0"} <= set(lines)
    assert d["J_std"] < d["J_u"]  # J_std keeps its meaning: the fit's 1σ alone
    # the published budget against a Monte Carlo propagation of the same inputs (JCGM 101)
    rig = read_rig(str(rig_file))
    assert rig.stiffness_std and rig.tare_inertia_std and rig.stiffness_tare_covariance and rig.clock_accuracy_ppm
    assert rig.stiffness is not None and rig.tare_inertia is not None
    rng = np.random.default_rng(5)
    n = 20_000
    cov = [[rig.stiffness_std**2, rig.stiffness_tare_covariance], [rig.stiffness_tare_covariance,
                                                                   rig.tare_inertia_std**2]]
    k, i0 = rng.multivariate_normal([rig.stiffness, rig.tare_inertia], cov, n).T
    w = sum(rng.normal(0.0, ln["std"], n) for ln in lines.values() if ln["unit"] == "rad/s") + d["omega_n"]
    w = w * (1 + rng.normal(0.0, rig.clock_accuracy_ppm * 1e-6, n))
    # one release: the documented default of the scatter between releases, counted (a relative factor on ω)
    assert lines["omega_n_repro"]["std"] == 0.001
    w = w * (1 + rng.normal(0.0, lines["omega_n_repro"]["std"], n))
    assert np.std(k / w**2 - i0) == pytest.approx(d["J_object_u"], rel=0.1)


@pytest.mark.parametrize(("line", "words"), [
    ('[sensor]\nclock_accuracy_ppm = "fast"\n', "clock_accuracy_ppm must be a number in ppm"),
    ("[rig]\nkind = \"torsion\"\nstiffness = 0.36\nstiffness_std = -1e-4\n", "stiffness_std must be >= 0"),
    ("[rig]\nkind = \"torsion\"\nstiffness = 0.36\nstiffness_std = 1e-4\ntare_inertia = 4e-3\n"
     "tare_inertia_std = 1e-6\nstiffness_tare_covariance = 1e-9\n", "not positive semi-definite"),
])
def test_a_bad_uncertainty_in_the_rig_file_is_one_line_and_exit_2(swing, tmp_path, capsys, line, words):
    rig = tmp_path / "rig.toml"
    rig.write_text(line if line.startswith("[rig]") else '[rig]\nkind = "torsion"\nstiffness = 0.36\n' + line)
    assert main(["identify", str(swing), "--rig", str(rig)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
