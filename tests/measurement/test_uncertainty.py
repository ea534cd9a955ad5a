"""The uncertainty budget (GUM, JCGM 100) against a Monte Carlo propagation (JCGM 101), the calibration's
errors-in-variables regression, and the verdict on the expanded uncertainty."""

from __future__ import annotations

import math

import numpy as np
import pytest

from measurement.calibration import Reference, calibrate_torsion
from measurement.errors import CalibrationError, InvalidInput, RigError
from measurement.reports import result_report
from measurement.rig import Rig
from measurement.uncertainty import Input, PendulumInputs, coverage_factor, evaluate
from measurement.verdict import INVALID, NOK, OK, QualityRules, Reading, Specification, combine, judge_release
from tests.judged import judged

DRAWS = 20_000


def _mc_check(draws: np.ndarray, budget) -> None:
    """The budget's u within 10 % of the draws' standard deviation, its U of their 95.45 % half-width."""
    assert np.std(draws) == pytest.approx(budget.u, rel=0.10)
    lo, hi = np.quantile(draws, [0.02275, 0.97725])
    assert (hi - lo) / 2 == pytest.approx(budget.U, rel=0.10)
    assert np.mean(draws) == pytest.approx(budget.value, abs=0.2 * budget.u)


def test_torsion_budget_agrees_with_monte_carlo_with_k_and_tare_correlated():
    # a calibration of the example rig from references known to 0.2–0.5 %: k and I0 strongly correlated
    k, I0 = 0.3651, 4.5043e-3
    refs = [Reference("empty", 0.0, math.sqrt(k / I0), 2e-4, 0.0),
            Reference("disc", 0.005, math.sqrt(k / (I0 + 0.005)), 2e-4, 2.5e-5),
            Reference("disc 2", 0.0125, math.sqrt(k / (I0 + 0.0125)), 2e-4, 5e-5)]
    cal = calibrate_torsion(refs)
    assert cal.correlation is not None and cal.correlation > 0.9
    J_true = 0.0125 + I0
    w = math.sqrt(k / J_true)
    inputs = PendulumInputs(omega_n=w, omega_n_std=3e-4, omega_n_dof=2000, omega_n_model=2e-4, clock_ppm=100,
                            rig_kind="torsion", stiffness=cal.stiffness, stiffness_std=cal.stiffness_std,
                            tare=cal.tare_inertia, tare_std=cal.tare_inertia_std, cov_k_tare=cal.covariance)
    budgets = inputs.budgets()
    b = budgets["J_object"]
    assert cal.stiffness_std is not None and cal.covariance is not None and cal.tare_inertia_std is not None
    rng = np.random.default_rng(7)
    cov = np.array([[cal.stiffness_std**2, cal.covariance], [cal.covariance, cal.tare_inertia_std**2]])
    kk, ii = rng.multivariate_normal([cal.stiffness, cal.tare_inertia], cov, DRAWS).T
    ww = (w + rng.normal(0, 3e-4, DRAWS) + rng.normal(0, 2e-4, DRAWS)) * (1 + rng.normal(0, 100e-6, DRAWS))
    _mc_check(kk / ww**2 - ii, b)
    # the correlation matters: treated as independent, J_object's u would be far off the Monte Carlo's
    independent = math.hypot(budgets["J"].u, cal.tare_inertia_std)
    assert independent > 1.3 * b.u
    assert b.correlations and b.correlations[0]["r"] == pytest.approx(cal.correlation)
    shares = sum(ln.share for ln in b.lines) + b.correlation_share
    assert shares == pytest.approx(1.0)
    names = {ln.symbol for ln in b.lines}
    assert {"omega_n_fit", "omega_n_model", "clock", "k", "I0"} <= names


def test_compound_budget_agrees_with_monte_carlo_through_the_m_g_s_product():
    m, S, g, L, mo = 2.0, 0.3, 9.81, 0.05, 0.4
    J = 0.25
    w = math.sqrt(m * g * S / J)
    inputs = PendulumInputs(omega_n=w, omega_n_std=2e-4, rig_kind="compound", mass=m, mass_std=2e-3,
                            com_distance=S, com_distance_std=1e-3, g=g, g_std=0.01, tare=0.05, tare_std=5e-4,
                            object_mass=mo, object_mass_std=1e-3, axis_offset=L, axis_offset_std=2e-3,
                            clock_ppm=50)
    budgets = inputs.budgets()
    rng = np.random.default_rng(11)
    mm, ss, gg = rng.normal(m, 2e-3, DRAWS), rng.normal(S, 1e-3, DRAWS), rng.normal(g, 0.01, DRAWS)
    ww = (w + rng.normal(0, 2e-4, DRAWS)) * (1 + rng.normal(0, 50e-6, DRAWS))
    JJ = mm * gg * ss / ww**2
    _mc_check(JJ, budgets["J"])
    axis = JJ - rng.normal(0.05, 5e-4, DRAWS) - rng.normal(mo, 1e-3, DRAWS) * rng.normal(L, 2e-3, DRAWS) ** 2
    _mc_check(axis, budgets["J_object_axis"])
    sens = {ln.symbol: ln.sensitivity for ln in budgets["J"].lines}
    assert sens["m"] == pytest.approx(J / m, rel=1e-6) and sens["S"] == pytest.approx(J / S, rel=1e-6)


def test_unstated_inputs_are_lines_with_zero_said_so():
    b = PendulumInputs(omega_n=5.0, omega_n_std=1e-4, rig_kind="compound", mass=1.0, com_distance=0.2,
                       g=9.80665).budgets()["J"]
    unstated = {ln.symbol: ln.note for ln in b.lines if not ln.stated}
    assert set(unstated) == {"clock", "m", "S", "g"}
    assert all("not stated" in n for n in unstated.values())
    assert b.u == pytest.approx(b.value * 2 * 1e-4 / 5.0, rel=1e-6)


def test_welch_satterthwaite_raises_the_coverage_factor_for_few_degrees_of_freedom():
    assert coverage_factor(math.inf) == 2.0
    assert coverage_factor(2) == pytest.approx(4.53, abs=0.01)
    b = evaluate("y", "1", lambda x: x["a"] + x["b"], [Input("a", "a", 1.0, 1.0, "1", dof=4),
                                                         Input("b", "b", 1.0, 1.0, "1")])
    # ν_eff = u⁴ / (u_a⁴/4) = 4·4 = 16
    assert b.dof == pytest.approx(16.0)
    assert b.coverage_factor == pytest.approx(2.17, abs=0.01)


def _gls_k_std(refs, b):
    """σ(k) from (AᵀWA)⁻¹ with the effective variances at slope b, written out independently."""
    I = np.array([r.added_inertia for r in refs])
    s2 = np.array([(2 * r.omega_n_std / r.omega_n**3) ** 2 + (b * r.added_inertia_std) ** 2 for r in refs])
    W = np.diag(1 / s2)
    A = np.column_stack([np.ones_like(I), I])
    cov = np.linalg.inv(A.T @ W @ A)
    return math.sqrt(cov[1, 1]) / b**2


def test_a_references_uncertainty_raises_ks_as_the_algebra_says_and_a_perfect_fit_does_not_shrink_it():
    k, I0 = 0.3651, 4.5043e-3

    def refs(u_disc):
        return [Reference("empty", 0.0, math.sqrt(k / I0), 1e-4, 0.0),
                Reference("disc", 0.005, math.sqrt(k / (I0 + 0.005)), 1e-4, u_disc),
                Reference("disc 2", 0.0125, math.sqrt(k / (I0 + 0.0125)), 1e-4, 1e-5)]

    small, large = calibrate_torsion(refs(1e-6)), calibrate_torsion(refs(1e-4))
    # the references lie exactly on the line (no misfit): σ still what the certificates allow
    for cal, u in ((small, 1e-6), (large, 1e-4)):
        assert cal.birge_ratio == pytest.approx(0.0, abs=1e-6)
        assert cal.stiffness_std == pytest.approx(_gls_k_std(refs(u), 1 / k), rel=1e-6)
    assert large.stiffness_std is not None and small.stiffness_std is not None
    assert large.stiffness_std > 1.5 * small.stiffness_std
    assert large.stiffness_std / k > 1e-4


def test_references_scattering_beyond_their_sigma_scale_it_up_by_the_birge_ratio():
    k, I0 = 0.3651, 4.5043e-3
    loads = [0.0, 0.003, 0.006, 0.009, 0.0125]
    rng = np.random.default_rng(3)
    true = [Reference(f"r{i}", L, math.sqrt(k / (I0 + L)), 1e-5, 1e-6) for i, L in enumerate(loads)]
    # the disc inertias are off by 30× their stated σ
    bad = [Reference(r.name, r.added_inertia + (3e-5 * rng.standard_normal() if r.added_inertia else 0.0),
                     r.omega_n, r.omega_n_std, r.added_inertia_std) for r in true]
    cal, ok = calibrate_torsion(bad), calibrate_torsion(true)
    assert cal.birge_ratio is not None and cal.birge_ratio > 3
    assert cal.stiffness_std is not None and ok.stiffness_std is not None and cal.stiffness_std > 3 * ok.stiffness_std
    assert any("Birge" in n for n in cal.notes)


def test_without_stated_uncertainties_the_calibration_says_the_misfit_alone_sets_sigma():
    k, I0 = 0.3651, 4.5043e-3
    refs = [Reference(f"r{i}", L, math.sqrt(k / (I0 + L)) * (1 + 1e-4 * (-1) ** i)) for i, L in
            enumerate((0.0, 0.005, 0.0125))]
    cal = calibrate_torsion(refs)
    assert cal.basis == "misfit" and cal.stiffness_std and "misfit alone" in cal.report()
    with pytest.raises(CalibrationError, match="standard uncertainty"):
        calibrate_torsion([Reference("a", 0.0, 9.0, -1e-3), Reference("b", 0.005, 6.0)])


def test_verdict_flips_from_ok_to_nok_and_invalid_as_the_guard_band_widens():
    spec = Specification.symmetric("J", 0.0125, 1e-4)
    verdicts = []
    for u_sys in (1e-6, 1e-5, 4e-5, 6e-5):
        r = Reading(0.01253, 1e-6, u_sys)
        verdicts.append(judge_release(r, spec, QualityRules()).verdict)
    assert verdicts == [OK, OK, NOK, NOK]  # the uncertain zone is NOK by default
    capped = judge_release(Reading(0.01253, 1e-6, 1.5e-5), spec, QualityRules(max_uncertainty_ratio=0.25))
    assert capped.verdict == INVALID and "half-tolerance" in capped.reasons[0]
    # the budget's own coverage factor (few degrees of freedom) widens U beyond the recipe's k = 2
    assert judge_release(Reading(0.01253, 1e-6, 2e-5), spec, QualityRules()).verdict == OK
    wide = judge_release(Reading(0.01253, 1e-6, 2e-5, coverage_factor=4.5), spec, QualityRules())
    assert wide.verdict == NOK and pytest.approx(4.5 * math.hypot(1e-6, 2e-5)) == wide.U


def test_part_of_three_scattered_releases_gets_students_t_for_two_degrees_of_freedom():
    spec = Specification.symmetric("J", 0.0125, 1e-3)
    part = combine([Reading(v, 1e-5, 0.0) for v in (0.01249, 0.01250, 0.01252)], spec, QualityRules())
    assert part.u_typeA is not None and part.u_fit is not None and part.uncertainty is not None
    assert part.decision.U is not None and part.decision.u_c is not None
    assert part.u_typeA > part.u_fit and len(part.used) == 3
    assert pytest.approx(coverage_factor(2) * part.decision.u_c, rel=1e-9) == part.decision.U
    assert part.decision.U / part.decision.u_c > 4
    lines = part.uncertainty["lines"]
    assert lines[0]["dof"] == 2 and lines[0]["u"] == part.u_typeA and part.uncertainty["dof"] == pytest.approx(2.0)


def test_reading_takes_the_budget_of_its_quantity():
    res = judged({"J_object": 0.0125}, 2e-7, 3e-6, coverage_factor=2.1, J=0.017)
    r = Reading.from_result(res, "J_object")
    assert (r.u_random, r.u_systematic, r.coverage_factor) == (2e-7, 3e-6, 2.1)


@pytest.mark.parametrize(("doc", "expected"), [
    ({"stiffness": 0.3, "stiffness_std": -1e-3}, "stiffness_std must be >= 0"),
    ({"stiffness": 0.3, "stiffness_std": "big"}, "stiffness_std must be a number"),
    ({"stiffness": 0.3, "stiffness_std": 1e-3, "tare_inertia": 4e-3, "tare_inertia_std": 1e-5,
      "stiffness_tare_covariance": 1e-7}, "not positive semi-definite"),
])
def test_bad_uncertainties_in_a_rig_file_say_what_was_expected(doc, expected):
    with pytest.raises(InvalidInput, match=expected):
        Rig.from_dict({"rig": {"kind": "torsion", **doc}})


def test_clock_accuracy_must_be_a_number_of_ppm():
    with pytest.raises(RigError, match="clock_accuracy_ppm must be a number in ppm"):
        Rig.from_dict({"rig": {"kind": "torsion"}, "sensor": {"clock_accuracy_ppm": "50 ppm"}})
    with pytest.raises(RigError, match="angle_scale_std is the σ of a calibrated sensor"):
        Rig.from_dict({"rig": {"kind": "torsion"}, "sensor": {"angle_scale_std": 1e-3}})
    rig = Rig.from_dict({"rig": {"kind": "compound", "mass": 1.0, "com_distance": 0.2, "mass_std": 1e-3,
                                 "g_std": 0.01}, "sensor": {"clock_accuracy_ppm": 20},
                         "object": {"mass": 0.3, "axis_offset": 0.1, "axis_offset_std": 1e-3}})
    assert Rig.from_dict(rig.to_dict()) == rig


def test_a_tensor_set_shares_k_and_the_tare_with_their_correlation():
    from measurement.tensor_inputs import RigShared

    rig = Rig(kind="torsion", stiffness=0.3651, stiffness_std=3.373e-4, tare_inertia=4.5043e-3,
              tare_inertia_std=4.177e-6, stiffness_tare_covariance=1.4076e-9)
    shared = RigShared.of(rig)
    assert shared.scale_tare_corr == pytest.approx(0.999, abs=1e-3)
    J = np.array([0.017, 0.012])
    # the same covariance the budget gives each J_object: k/ω² − I0 with k and I0 correlated
    for i, Ji in enumerate(J):
        b = PendulumInputs(omega_n=math.sqrt(rig.stiffness / Ji), omega_n_std=0.0, stiffness=rig.stiffness,
                           stiffness_std=rig.stiffness_std, tare=rig.tare_inertia, tare_std=rig.tare_inertia_std,
                           cov_k_tare=rig.stiffness_tare_covariance).budgets()["J_object"]
        assert math.sqrt(shared.common_covariance(J)[i, i]) == pytest.approx(b.u, rel=1e-4)


def test_the_budgets_with_their_correlation_read_back_as_the_json_they_were_written_as():
    # k and the tare correlated, an object moved to its own axis: every budget a result can carry, with
    # Type B lines (infinite degrees of freedom, written null); what from_dict reads, to_dict writes again
    import json

    from measurement import Pendulum, identify, simulate_trace
    from measurement.result import IdentificationResult
    from measurement.rig import ObjectTransfer

    rig = Rig(kind="torsion", stiffness=0.3651, stiffness_std=3.373e-4, tare_inertia=4.5043e-3,
              tare_inertia_std=4.177e-6, stiffness_tare_covariance=1.4076e-9,
              object=ObjectTransfer(mass=0.8, axis_offset=0.05, mass_std=1e-3), declared=("viscous",))
    trace = simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}}), theta0=0.2, duration=8, rate=100,
                           noise_std=1e-4, seed=2)
    r = identify(trace, rig)
    assert set(r.uncertainty_budget) == {"J", "J_object", "J_object_axis"}
    assert r.uncertainty_budget["J_object"].correlations  # the k–I0 term
    text = r.to_json()
    back = IdentificationResult.from_dict(json.loads(text))
    assert back.to_json() == text and result_report(back) == result_report(r)
    assert back.uncertainty_budget["J_object"].U == r.uncertainty_budget["J_object"].U
    assert back.uncertainty_budget["J"].lines == r.uncertainty_budget["J"].lines
