"""Releases of one object recorded by other people on their own rigs must agree within the uncertainty moi states.

The sets in data/ (a cart pendulum on an encoder, four releases from 21° to
179°; a bifilar suspension read by an IMU, two releases): whatever the
release angle, the physics identified from one object is the same.
Agreement of the releases, not a low residual on one of them, is how the
model is shown true; where the model does not hold across a record, the
result must say so and carry it in its uncertainty.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
from pathlib import Path

import pytest

from measurement.joint import JointResult, identify_releases
from measurement.reports import result_report
from measurement.result import IdentificationResult
from service.sources.dispatch import load_source
from service.sources.files import read_rig

ROOT = Path(__file__).resolve().parents[2]
SETS = {
    "cart": ([f"data/cart_pendulum_{a}deg.csv" for a in (20, 40, 80, 180)], "examples/cart_pendulum.toml"),
    "bifilar": ([f"data/bifilar_yaw_{a}deg.csv" for a in (65, 86)], "examples/bifilar_yaw.toml"),
}


@functools.cache
def joint(name: str):
    files, rig = SETS[name]
    return identify_releases([load_source(ROOT / f) for f in files], read_rig(ROOT / rig))


@pytest.mark.parametrize("name", sorted(SETS))
def test_releases_agree_within_their_stated_uncertainty(name):
    j = joint(name)
    for a, b in itertools.combinations(j.releases, 2):
        z = abs(a.omega_n - b.omega_n) / math.hypot(a.omega_n_u, b.omega_n_u)
        assert z <= 2.0, (name, a.source, b.source, a.omega_n, b.omega_n, a.omega_n_u, b.omega_n_u)
    c = j.consistency
    assert c["p"] >= 0.01 and "releases_disagree" not in j.flags, c
    assert abs(c["largest_z"]) <= 2.5 and c["pairwise_max"] <= 2.0


def test_the_cart_pendulum_from_upright_agrees_with_its_small_releases():
    j = joint("cart")
    w = [r.omega_n for r in j.releases]
    # within 0.1 %, the release from 179° included (it slipped a cycle before: 0.9 % low)
    assert (max(w) - min(w)) / min(w) < 1e-3
    upright = j.releases[-1]
    assert {"coulomb", "quadratic"} <= set(upright.effects)
    assert upright.residual_rms < 2 * upright.noise_floor


def test_an_imu_scale_is_not_fitted_for_a_law_that_is_not_sin_theta():
    j = joint("bifilar")
    for r in j.releases:
        # a gain would differ between the record's halves: it stands for the restoring law, not the sensor
        assert not {"gain", "view"} & set(r.effects)
        assert any("gain does not hold across the record" in s.reason for s in r.steps)
        # the model does not hold across the record, and the result says so and by how much (well above
        # the fit's σ, which takes in some of the same structure from the record's own residual)
        assert "halves_disagree" in r.flags and r.omega_n_std_model > 3 * r.omega_n_std


def test_presliding_friction_that_moves_omega_n_without_holding_is_withdrawn():
    # with dahl the two bifilar releases were 1.1 % apart (and the cart's 20° release 0.05 % from
    # the others): the model with it gives another ω_n in each half of the record, so it is not kept,
    # and its ω_n stays a rival in the uncertainty
    for name in ("bifilar", "cart"):
        for r in joint(name).releases:
            if any("dahl lowered BIC" in s for s in r.structure):
                assert "dahl" not in r.effects and "model_ambiguous" in r.flags
    w = [r.omega_n for r in joint("bifilar").releases]
    assert "dahl" not in joint("bifilar").releases[0].effects
    assert (max(w) - min(w)) / min(w) < 2e-3


def test_a_joint_fit_apart_from_the_releases_value_widens_the_joint_uncertainty():
    from measurement.joint import FIT_APART_Z, with_joint_fit

    # agreeing within their uncertainties: the joint u is the releases' own
    assert with_joint_fit(5.7724, 0.0013, 5.7730, 0.0001) == (0.0013, pytest.approx(0.6 / math.hypot(1.3, 0.1)))
    # apart (the shared laws do not hold over the releases' amplitudes): the distance enters u
    u, z = with_joint_fit(5.77235, 0.00008, 5.77365, 0.00006)
    assert z > FIT_APART_Z and u == pytest.approx(math.hypot(0.00008, 0.0013)) and u > 0.0013
    # the real sets' joint fits agree with their releases' value: nothing is widened or flagged
    for name in SETS:
        fit = joint(name).consistency["joint_fit"]
        assert not fit["apart"] and fit["z"] <= FIT_APART_Z, (name, fit)


def test_shared_laws_of_least_bic_that_do_not_hold_across_a_release_are_not_kept():
    # the bifilar's releases together prefer Coulomb friction with a cubic law (ΔBIC thousands),
    # but with it the halves of each record disagree more than under its own model: BIC alone
    # does not make a law true, so the releases' own laws stay and the distance enters u
    j = joint("bifilar")
    c = j.consistency
    best = min(c["models"], key=lambda m: m["d_bic"])
    assert "cubic_stiffness" in best["effects"] and not best["chosen"]
    assert c["not_held"] and j.effects == ("viscous", "coulomb")
    assert c["u_models"] >= abs(best["omega_n"] - c["joint_fit"]["omega_n"])
    assert j.omega_n_u >= c["u_models"]


@pytest.mark.parametrize("name", sorted(SETS))
def test_a_joint_result_and_its_releases_read_back_as_the_json_they_were_written_as(name):
    # the result JSON is a contract read outside the repo: what from_dict reads, to_dict writes again byte for byte
    j = joint(name)
    text = j.to_json()
    again = JointResult.from_dict(json.loads(text))
    assert again.to_json() == text
    assert {k: b.U for k, b in again.uncertainty_budget.items()} == {k: b.U for k, b in j.uncertainty_budget.items()}
    assert bool(j.uncertainty_budget) == (name == "cart")  # the cart's rig gives J, the bifilar's does not
    for r, back in zip(j.releases, again.releases):
        assert back.model_form == r.model_form and back.diagnostics == r.diagnostics
        assert back.uncertainty_budget.keys() == r.uncertainty_budget.keys()
        assert back.J_U == r.J_U and result_report(back) == result_report(r)
        with_arrays = r.to_json(include_arrays=True)
        assert IdentificationResult.from_dict(json.loads(with_arrays)).to_json(include_arrays=True) == with_arrays
