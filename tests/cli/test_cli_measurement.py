"""`moi identify/simulate/calibrate` through the real command line (subprocess)."""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TORSION_RIG = '[rig]\nkind = "torsion"\nstiffness = 0.3651\ntare_inertia = 4.5043e-3\n[model]\ndeclared = ["viscous"]\n'


def moi(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "service.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, timeout=120)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    (d / "rig.toml").write_text(TORSION_RIG)
    r = moi("simulate", "--rig", d / "rig.toml", "--inertia", 0.0125, "--effects", "viscous=1.5e-4", "coulomb:Tc=1.2e-4",
            "--theta0", 0.25, "--duration", 20, "--rate", 200, "--noise", 1e-4, "--bits", 17, "--pre-trigger", 0.5,
            "--seed", 4, "--out", d / "trace.csv")
    assert r.returncode == 0, r.stderr
    return d


def test_identify_json_contract(files):
    r = moi("identify", files / "trace.csv", "--rig", files / "rig.toml", "--json", "--plot", files / "fit.png")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    for key in ("J", "J_std", "omega_n", "effects", "added_effects", "damping", "residual_rms", "baseline", "flags"):
        assert key in d
    assert set(d["baseline"]) >= {"effects", "J", "omega_n", "residual_rms"}
    assert d["J"] == pytest.approx(0.0125, rel=1e-3)
    assert d["added_effects"] == ["coulomb"] and d["baseline"]["effects"] == ["viscous"]
    assert d["omega_n"] == pytest.approx(math.sqrt(0.3651 / 0.0125), rel=1e-4)
    png = (files / "fit.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000


def test_identify_report_is_readable(files):
    r = moi("identify", files / "trace.csv", "--rig", files / "rig.toml")
    assert r.returncode == 0, r.stderr
    assert "J            =" in r.stdout and "kg·m²" in r.stdout and "added    : coulomb" in r.stdout


def test_calibrate_writes_a_rig(tmp_path):
    cal = tmp_path / "cal.toml"
    cal.write_text("""
[[reference]]
name = "empty"
omega = 9.0017
zeta = -0.05197
added_inertia = 0.0
[[reference]]
name = "L=50mm"
omega = 6.9930
zeta = -0.06017
cylinders = [{mass = 0.5021, diameter = 0.06007, distance = 0.05}, {mass = 0.5006, diameter = 0.06004, distance = 0.05}]
[[reference]]
name = "L=75mm"
omega = 5.8686
zeta = -0.06579
cylinders = [{mass = 0.5021, diameter = 0.06007, distance = 0.075}, {mass = 0.5006, diameter = 0.06004, distance = 0.075}]
[[reference]]
name = "L=100mm"
omega = 4.9352
zeta = -0.07123
cylinders = [{mass = 0.5021, diameter = 0.06007, distance = 0.10}, {mass = 0.5006, diameter = 0.06004, distance = 0.10}]
""")
    (tmp_path / "rig.toml").write_text('[rig]\nkind = "torsion"\n')
    r = moi("calibrate", cal, "--rig", tmp_path / "rig.toml", "--out", tmp_path / "out.toml", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["stiffness"] == pytest.approx(0.3651, rel=1e-3)
    import tomllib
    rig = tomllib.loads((tmp_path / "out.toml").read_text())["rig"]
    assert rig["stiffness"] == pytest.approx(d["stiffness"]) and rig["tare_inertia"] == pytest.approx(4.5043e-3, rel=1e-3)


def test_calibrate_records_date_validity_and_references_and_an_expired_one_flags_calibration_due(tmp_path):
    cal = tmp_path / "cal.toml"
    cal.write_text("""
[[reference]]
name = "empty"
omega_n = 9.0
added_inertia = 0.0
[[reference]]
name = "disc A"
omega_n = 7.0
added_inertia = 0.00295
added_inertia_std = 2e-6
[[reference]]
name = "disc B"
omega_n = 5.9
added_inertia = 0.00584
added_inertia_std = 3e-6
""")
    (tmp_path / "rig.toml").write_text('[rig]\nkind = "torsion"\n')
    r = moi("calibrate", cal, "--rig", tmp_path / "rig.toml", "--out", tmp_path / "out.toml", "--date", "2024-03-01",
            "--valid-days", "180", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["valid_until"] == "2024-08-28"
    import datetime
    import tomllib

    from measurement.rig import Rig
    doc = tomllib.loads((tmp_path / "out.toml").read_text())
    assert doc["calibration"]["date"] == "2024-03-01" and doc["calibration"]["valid_days"] == 180
    refs = {r["name"]: r for r in doc["calibration"]["references"]}
    assert refs["disc B"]["added_inertia_std"] == 3e-6 and refs["disc A"]["omega_n"] == 7.0
    assert "added_inertia_std" not in refs["empty"] and "inertia_residual" in refs["empty"]
    assert doc["rig"]["stiffness_std"] > 0  # three references: k has an uncertainty, which enters U
    rig = Rig.from_dict(doc)
    assert rig.calibration is not None
    assert rig.calibration.due(datetime.date(2024, 8, 29)) and not rig.calibration.due(datetime.date(2024, 8, 28))
    r = moi("calibrate", cal, "--rig", tmp_path / "rig.toml", "--date", "March 1st")
    assert r.returncode == 2 and "--date must be a date" in r.stderr


GOOD_HEADER = "t,angle\n"


def _rows(n=400, dt=0.005):
    return "".join(f"{i * dt:.4f},{0.2 * math.cos(6 * i * dt):.6f}\n" for i in range(n))


BAD_TRACES = {
    "missing": (None, "not found"),
    # a column named theta is an angle (read as a table); one named otherwise is none
    "no_angle_column": ("t,foo\n" + _rows(), "no angle, rate or x/y position column among 'foo'"),
    "non_numeric": (GOOD_HEADER + _rows(10) + "0.5,abc\n" + _rows(10), "non-numeric"),
    "non_monotonic": (GOOD_HEADER + "0.0,0.1\n0.2,0.1\n0.1,0.1\n", "not strictly increasing"),
    "empty": (GOOD_HEADER, "empty"),
    "nan_gap": (GOOD_HEADER + "0.0,0.1\n0.01,nan\n0.02,0.1\n", "NaN"),
    "too_few_swings": (GOOD_HEADER + _rows(150), "swing"),
}


@pytest.mark.parametrize("case", list(BAD_TRACES))
def test_bad_trace_gives_one_line_and_exit_2(case, tmp_path):
    content, message = BAD_TRACES[case]
    (tmp_path / "rig.toml").write_text(TORSION_RIG)
    path = tmp_path / "trace.csv"
    if content is not None:
        path.write_text(content)
    r = moi("identify", path, "--rig", tmp_path / "rig.toml")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], r.stderr
    assert "Traceback" not in r.stderr


BAD_RIGS = {
    "unknown_kind": ('[rig]\nkind = "quadrifilar"\n', "unknown kind"),
    "bifilar_without_wires": ('[rig]\nkind = "bifilar"\n', "a bifilar rig needs wire_length (m) and spacing (m)"),
    "unknown_effect": ('[rig]\nkind = "torsion"\nstiffness = 1.0\n[model]\ndeclared = ["magic"]\n', "unknown effect"),
    "zero_stiffness": ('[rig]\nkind = "torsion"\nstiffness = 0.0\n', "stiffness must be > 0"),
    "negative_mass": ('[rig]\nkind = "compound"\nmass = -5.0\ncom_distance = 1.0\n', "mass must be > 0"),
    "bad_toml": ('[rig\nkind = "torsion"\n', "not valid TOML"),
    "typo_key": ('[rig]\nkind = "torsion"\nstifness = 1.0\n', "unknown key"),
    "missing_file": (None, "not found"),
}


@pytest.mark.parametrize("case", list(BAD_RIGS))
def test_bad_rig_gives_one_line_and_exit_2(case, files, tmp_path):
    content, message = BAD_RIGS[case]
    rig = tmp_path / "rig.toml"
    if content is not None:
        rig.write_text(content)
    r = moi("identify", files / "trace.csv", "--rig", rig)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], r.stderr


def test_unknown_effect_in_simulate_is_exit_2(files, tmp_path):
    r = moi("simulate", "--rig", files / "rig.toml", "--inertia", 0.01, "--effects", "friction=1", "--out", tmp_path / "x.csv")
    assert r.returncode == 2 and "unknown effect 'friction'" in r.stderr


def test_calibrate_from_traces_of_known_loads(tmp_path):
    """Empty fixture and two known loads, recorded as traces, give back k and I0."""
    k, I0 = 0.3651, 4.5043e-3
    (tmp_path / "rig.toml").write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n')
    refs = []
    for i, added in enumerate((0.0, 3.0e-3, 8.0e-3)):
        out = tmp_path / f"ref{i}.csv"
        r = moi("simulate", "--rig", tmp_path / "rig.toml", "--inertia", I0 + added, "--effects", "viscous=1e-4",
                "--duration", 20, "--noise", 1e-4, "--bits", 17, "--seed", i, "--out", out)
        assert r.returncode == 0, r.stderr
        refs.append(f'[[reference]]\nname = "load {i}"\ntrace = "{out.name}"\nadded_inertia = {added}\n')
    (tmp_path / "cal.toml").write_text("\n".join(refs))
    (tmp_path / "empty_rig.toml").write_text('[rig]\nkind = "torsion"\n')
    r = moi("calibrate", tmp_path / "cal.toml", "--rig", tmp_path / "empty_rig.toml", "--json",
            "--out", tmp_path / "calibrated.toml")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["stiffness"] == pytest.approx(k, rel=1e-4)
    assert d["tare_inertia"] == pytest.approx(I0, rel=1e-4)
    assert d["stiffness_std"] < 1e-4 * k
    # the amplitude the references' ω_n were read at is kept with the calibration: a part's ω is read there too
    import tomllib

    written = tomllib.loads((tmp_path / "calibrated.toml").read_text(encoding="utf-8"))
    assert 0.05 < written["calibration"]["amplitude"] < 0.3
