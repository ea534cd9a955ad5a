"""`moi calibrate` with references released more than once keeps the rig's reproducibility between releases with its
calibration (ISO 5725-2 pooled, against numpy); one release identified on that rig counts it (source "rig"), on a rig
without it the documented default."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from measurement import Options, Pendulum, identify, simulate_trace
from measurement.reproducibility import DEFAULT, RIG
from service.cli import main
from service.sources.files import read_rig

REPO = Path(__file__).resolve().parents[2]
RIG_FILE = str(REPO / "examples" / "torsion_rig.toml")
K, I0 = 0.3651, 4.5043e-3
#: each reference's releases: ω_n off the true one by the pivot settling anew (relative)
RELEASES = {"empty fixture": (0.0, (0.0011, -0.0006)), "disc 5 g·m²": (0.005, (-0.0009, 0.0004, 0.0012)),
            "disc 12.5 g·m²": (0.0125, (0.0002,))}


def _cal_text(releases=RELEASES) -> str:
    tables = []
    for name, (added, offs) in releases.items():
        for off in offs:
            w = math.sqrt(K / (I0 + added)) * (1 + off)
            tables.append(f'[[reference]]\nname = "{name}"\nadded_inertia = {added}\nadded_inertia_std = '
                          f'{2e-3 * added}\nomega_n = {w!r}\nomega_n_std = 2e-4\n')
    return "\n".join(tables)


def _numpy_pooled() -> tuple[float, int]:
    ss, dof = 0.0, 0
    for added, offs in RELEASES.values():
        w = np.sqrt(K / (I0 + added)) * (1 + np.array(offs))
        if w.size > 1:
            ss += float(np.sum((w / w.mean() - 1) ** 2))
            dof += w.size - 1
    return math.sqrt(ss / dof), dof


def _calibrated_rig(tmp_path: Path, capsys) -> Path:
    (tmp_path / "cal.toml").write_text(_cal_text())
    out = tmp_path / "rig.toml"
    assert main(["calibrate", str(tmp_path / "cal.toml"), "--rig", RIG_FILE, "--out", str(out)]) == 0
    assert "kept with the calibration, in one release's u" in capsys.readouterr().out
    return out


def _part(rig):
    truth = read_rig(RIG_FILE)
    return identify(simulate_trace(Pendulum(truth, I0 + 0.01, effects={"viscous": {"c": 2e-4}}), theta0=0.3,
                                   duration=10, rate=100, noise_std=2e-4, seed=4), rig, Options(discover=False))


def test_references_released_twice_keep_the_pooled_figure_and_its_dof_in_the_rig_file(tmp_path, capsys):
    rig = read_rig(str(_calibrated_rig(tmp_path, capsys)))
    relative, dof = _numpy_pooled()
    assert rig.calibration is not None and dof == 3  # (2 − 1) + (3 − 1)
    assert rig.calibration.reproducibility == pytest.approx(relative, rel=1e-9)
    assert rig.calibration.reproducibility_dof == dof
    figure = rig.reproducibility
    assert figure is not None and (figure.source, figure.groups, figure.releases) == (RIG, 2, 5)
    # each release is a point of k's fit: six points, one per release
    assert len(rig.calibration.references) == 6


def test_a_part_on_that_rig_counts_its_calibration_figure(tmp_path, capsys):
    rig = read_rig(str(_calibrated_rig(tmp_path, capsys)))
    res = _part(rig)
    assert res.reproducibility == rig.reproducibility and res.reproducibility.counted
    line = next(ln for ln in res.uncertainty_budget["J"].lines if ln.symbol == "omega_n_repro")
    assert line.std == pytest.approx(_numpy_pooled()[0]) and line.dof == 3
    assert res.to_dict()["reproducibility"]["source"] == "rig"


def test_a_rig_without_the_figure_counts_the_default(tmp_path):
    rig = read_rig(RIG_FILE)
    assert rig.reproducibility is None
    res = _part(rig)
    assert res.reproducibility == DEFAULT and DEFAULT.counted
    b = res.uncertainty_budget["J"]
    line = next(ln for ln in b.lines if ln.symbol == "omega_n_repro")
    # 0.1 % of ω_n (relative, in ω's terms), 0.2 % of J in the budget
    assert line.std == 0.001 and abs(line.contribution) == pytest.approx(2e-3 * b.value, rel=1e-6)


def test_once_released_references_keep_no_figure_and_say_so(tmp_path, capsys):
    (tmp_path / "cal.toml").write_text((REPO / "examples" / "calibration.toml").read_text())
    out = tmp_path / "rig.toml"
    assert main(["calibrate", str(tmp_path / "cal.toml"), "--rig", RIG_FILE, "--out", str(out)]) == 0
    assert "not measured (each reference released once)" in capsys.readouterr().out
    assert read_rig(str(out)).reproducibility is None
    assert "reproducibility" not in out.read_text()


def test_one_name_with_two_known_inertias_is_refused(tmp_path, capsys):
    text = _cal_text().replace("added_inertia = 0.005\n", "added_inertia = 0.0051\n", 1)
    (tmp_path / "cal.toml").write_text(text)
    assert main(["calibrate", str(tmp_path / "cal.toml"), "--rig", RIG_FILE]) == 2
    assert "given with different known inertias" in capsys.readouterr().err


@pytest.mark.parametrize("keys", ['reproducibility = 0.001', 'reproducibility = 0.001\nreproducibility_dof = 0',
                                  'reproducibility = -0.001\nreproducibility_dof = 3'])
def test_a_rig_files_figure_without_its_dof_or_out_of_range_is_refused(tmp_path, keys, capsys):
    path = tmp_path / "rig.toml"
    path.write_text(Path(RIG_FILE).read_text() + f'\n[calibration]\ndate = 2026-01-31\n{keys}\n')
    assert main(["identify", str(REPO / "examples" / "calibration.toml"), "--rig", str(path)]) == 2
    assert "[calibration] reproducibility" in capsys.readouterr().err


def test_calibrating_in_place_again_with_once_released_references_drops_the_old_figure(tmp_path, capsys):
    out = _calibrated_rig(tmp_path, capsys)
    assert read_rig(str(out)).reproducibility is not None
    (tmp_path / "once.toml").write_text((REPO / "examples" / "calibration.toml").read_text())
    assert main(["calibrate", str(tmp_path / "once.toml"), "--rig", str(out), "--out", str(out)]) == 0
    rig = read_rig(str(out))
    assert rig.calibration is not None and rig.calibration.source == str(tmp_path / "once.toml")
    assert rig.reproducibility is None and "reproducibility" not in out.read_text()


def test_one_reference_released_twice_is_too_thin_to_keep(tmp_path, capsys):
    # ν = 1: a Type A line of one degree of freedom setting u would set k near 13
    once = {name: (added, offs[:1]) for name, (added, offs) in RELEASES.items()}
    (tmp_path / "cal.toml").write_text(_cal_text(once | {"empty fixture": RELEASES["empty fixture"]}))
    out = tmp_path / "rig.toml"
    assert main(["calibrate", str(tmp_path / "cal.toml"), "--rig", RIG_FILE, "--out", str(out)]) == 0
    assert "fewer than 2 degrees of freedom: not kept" in capsys.readouterr().out
    assert read_rig(str(out)).reproducibility is None
