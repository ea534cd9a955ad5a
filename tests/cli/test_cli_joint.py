"""`moi identify A.csv B.csv ... --rig R`: several releases of one object identified jointly."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.cli import main

ROOT = Path(__file__).resolve().parents[2]
RELEASES = [str(ROOT / "data" / f"cart_pendulum_{a}deg.csv") for a in (20, 40)]
RIG = str(ROOT / "examples" / "cart_pendulum.toml")


def test_two_releases_give_one_joint_answer_with_a_consistency_test(capsys):
    assert main(["identify", *RELEASES, "--rig", RIG, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["joint"] is True and len(d["releases"]) == 2
    for key in ("J", "J_std", "J_u", "omega_n", "omega_n_u", "effects", "added_effects", "damping", "flags"):
        assert key in d
    c = d["consistency"]
    assert c["dof"] == 1 and 0.0 <= c["p"] <= 1.0 and len(c["z"]) == 2
    # the joint value lies between the releases, each weighed by its uncertainty
    lo, hi = sorted(c["omega_n"])
    assert lo <= d["omega_n"] <= hi
    assert d["omega_n_u"] >= d["omega_n_std"] > 0
    # the joint value has its own budget: the joint ω_n and the rig's constants
    b = d["uncertainty_budget"]["J"]
    # no m, S, g stated (the rig file says none): U is 2 × the ω_n term's u alone, the lines say so
    assert d["J_U"] == b["U"] == pytest.approx(2 * d["J_u"], rel=1e-6)
    assert {ln["symbol"] for ln in b["lines"]} >= {"omega_n_fit", "m", "S", "g"}


def test_the_report_lists_each_release_and_the_verdict_on_their_agreement(capsys):
    assert main(["identify", *RELEASES, "--rig", RIG]) == 0
    out = capsys.readouterr().out
    assert "[[Joint identification]] 2 releases" in out
    assert all(Path(r).name in out for r in RELEASES)
    assert "agree with one ω_n" in out or "disagree beyond" in out


def test_a_plot_of_several_releases_is_refused_with_one_line(capsys, tmp_path):
    assert main(["identify", *RELEASES, "--rig", RIG, "--plot", str(tmp_path / "p.png")]) == 2
    err = capsys.readouterr().err
    assert "one SOURCE" in err and "Traceback" not in err
