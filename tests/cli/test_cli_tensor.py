"""`moi tensor PLAN.toml`: the example plan end to end, and bad plans as one line with exit 2."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from measurement import tensor as TS
from measurement.simulate import BRACKET
from service.cli import main

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "tensor" / "bracket.toml"


def test_the_example_plan_gives_the_bracket_tensor_as_json_and_a_plot(tmp_path):
    r = subprocess.run([sys.executable, "-m", "service.cli", "tensor", str(EXAMPLE), "--json",
                        "--plot", str(tmp_path / "tensor.png")], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    for key in ("tensor", "tensor_cov", "tensor_U", "principal_moments", "principal_moments_U", "principal_axes",
                "principal_axes_U_deg", "poi_convention", "condition_number", "chi2", "dof", "orientations", "flags"):
        assert key in d, key
    sigma = np.sqrt(np.diag(d["tensor_cov"]))
    z = (TS.entries_of(d["tensor"]) - TS.entries_of(BRACKET.tensor)) / sigma
    assert np.all(np.abs(z) <= 2.0), z
    assert d["poi_convention"] == "negative" and d["components"]["Ixy"] == pytest.approx(-1.5e-3, rel=1e-3)
    x = d["orientations"][0]
    assert x["name"] == "x" and len(x["traces"]) == 2 and x["releases"]["used"] == [0, 1]
    assert x["parallel_axis"] == pytest.approx(1.25 * (0.03**2 + 0.02**2))
    assert (tmp_path / "tensor.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def plan_copy(tmp_path: Path, edit) -> Path:
    """The example plan and its traces in tmp_path, the plan's text passed through ``edit``."""
    d = tmp_path / "plan"
    shutil.copytree(EXAMPLE.parent, d)
    shutil.copy(ROOT / "examples" / "torsion_rig.toml", tmp_path / "torsion_rig.toml")
    (d / "bracket.toml").write_text(edit((d / "bracket.toml").read_text()))
    return d / "bracket.toml"


def drop_last_orientation(text: str) -> str:
    return text[:text.rindex("[[orientation]]")]


BAD = {
    "fewer than 6 orientations": (drop_last_orientation, "at least 6"),
    "a zero axis": (lambda s: s.replace("axis = [0, 1, 1]", "axis = [0, 0, 0]"), "zero vector"),
    "a rank-deficient plan": (lambda s: s.replace("axis = [0, 1, 1]", "axis = [0, 1, 0]"), "rank"),
    "a missing trace": (lambda s: s.replace('"z_1.csv"', '"z_9.csv"'), "not found"),
    "an offset without a mass": (lambda s: s.replace("mass = 1.25", "").replace("mass_std = 1e-4", ""), "no mass"),
    "an unknown convention": (lambda s: s.replace('poi_convention = "negative"', 'poi_convention = "minus"'),
                              "poi_convention"),
    "no rig": (lambda s: s.replace('rig = "../torsion_rig.toml"', ""), "rig ="),
    "no traces": (lambda s: s.replace('traces = ["y_1.csv"]', ""), "traces"),
    "a malformed file": (lambda s: s + "\n[[orientation\n", "not valid TOML"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_plan_is_one_line_and_exit_2(case, tmp_path, capsys):
    edit, message = BAD[case]
    plan = plan_copy(tmp_path, edit)
    assert main(["tensor", str(plan)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0], err


def test_a_compound_rig_is_refused(tmp_path, capsys):
    plan = plan_copy(tmp_path, lambda s: s)
    (tmp_path / "torsion_rig.toml").write_text('[rig]\nkind = "compound"\nmass = 2.0\ncom_distance = 0.3\n')
    assert main(["tensor", str(plan)]) == 2
    assert "torsion rig" in capsys.readouterr().err
