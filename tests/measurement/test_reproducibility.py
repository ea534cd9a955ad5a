"""Reproducibility between releases: the pooled within-group standard deviation of repeat releases
(ISO 5725-2) against a hand computation, its line in the budget, and what one release says without it."""

from __future__ import annotations

import math

import pytest

from measurement import Options, Pendulum, Rig, identify, simulate_trace
from measurement.reports import result_report
from measurement.reproducibility import DEFAULT, HISTORY, MIN_DOF, RIG, ReproducibilityError, calibrated, for_release, pooled
from measurement.result import IdentificationResult
from measurement.uncertainty import PendulumInputs


def test_pooled_is_the_hand_computed_iso_5725_within_group_deviation():
    # group 1: mean 1.00, relative deviations 0, +0.02, −0.02 → Σ = 0.0008, 2 degrees of freedom
    # group 2: mean 2.02, relative deviations ±0.02/2.02 → Σ = 2·(0.02/2.02)², 1 degree of freedom
    # group 3: one release, says nothing about the scatter between releases
    r = pooled([[1.00, 1.02, 0.98], [2.0, 2.04], [7.0]])
    hand = math.sqrt((0.0008 + 2 * (0.02 / 2.02) ** 2) / 3)
    assert r.relative == pytest.approx(hand, rel=1e-12)
    assert hand == pytest.approx(0.0182215, rel=1e-5)
    assert (r.dof, r.groups, r.releases, r.source, r.counted) == (3.0, 2, 5, HISTORY, True)
    assert r.known


def test_pooled_inertias_give_the_scatter_of_omega_n():
    # J = C/ω²: a relative scatter δ of ω_n is about 2δ of J
    omegas = [[4.0, 4.004, 3.996], [6.0, 6.006, 5.994, 6.0]]
    J = [[1.0 / w**2 for w in g] for g in omegas]
    assert pooled(J, power=-2).relative == pytest.approx(pooled(omegas).relative, rel=2e-3)


def test_no_group_of_two_releases_is_not_known():
    r = pooled([[4.0], [5.0]])
    assert r.relative is None and r.dof == 0 and not r.known and not r.counted


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_a_value_that_is_no_positive_number_is_refused(bad):
    with pytest.raises(ReproducibilityError, match="positive number"):
        pooled([[1.0, bad]])


def _inputs(repro):
    return PendulumInputs(omega_n=4.0, omega_n_std=1e-4, omega_n_dof=500, clock_ppm=20, stiffness=0.36,
                          stiffness_std=3e-4, reproducibility=repro)


def test_a_history_enters_u_with_its_degrees_of_freedom():
    without = _inputs(None).budgets()["J"]
    r = pooled([[4.0, 4.004, 3.996], [6.0, 6.006]])
    with_it = _inputs((r.relative, r.dof, r.counted, r.note())).budgets()["J"]
    added = 2 * without.value * r.relative  # J = k/ω²: c·u = −2·J·δ
    assert with_it.u**2 == pytest.approx(without.u**2 + added**2, rel=1e-6)
    line = next(ln for ln in with_it.lines if ln.symbol == "omega_n_repro")
    assert line.stated and line.dof == r.dof and line.kind == "random"
    assert with_it.dof < 1e6 and with_it.coverage_factor > 2.0  # 3 degrees of freedom widen k


def test_the_default_is_counted_in_u_as_a_type_b_line():
    without = _inputs(None).budgets()["J"]
    d = DEFAULT
    b = _inputs((d.relative, d.dof, d.counted, d.note())).budgets()["J"]
    added = 2 * without.value * d.relative  # J = k/ω²: 0.1 % of ω_n is 0.2 % of J
    assert b.u**2 == pytest.approx(without.u**2 + added**2, rel=1e-6)
    line = next(ln for ln in b.lines if ln.symbol == "omega_n_repro")
    assert line.stated and line.std == d.relative and line.contribution == pytest.approx(-added, rel=1e-6)
    assert "measure ≥ 3 releases" in line.note
    assert "0.1 % of ω_n" in line.note and "0.2 % of J" in line.note and "is in u" in line.note
    # taken at its value (ν = ∞): k stays that of the record's own lines
    assert d.counted and math.isinf(d.dof) and b.coverage_factor == pytest.approx(without.coverage_factor)


def _release():
    rig = Rig(kind="torsion", stiffness=0.36, stiffness_std=3e-4, declared=("viscous",))
    trace = simulate_trace(Pendulum(rig, 0.0125, effects={"viscous": {"c": 1e-4}}), theta0=0.2, duration=15, rate=100,
                           noise_std=1e-4, seed=3)
    return rig, trace


def test_one_release_says_reproducibility_is_not_known_and_a_history_counts():
    rig, trace = _release()
    alone = identify(trace, rig, Options(discover=False))
    assert alone.reproducibility == DEFAULT
    assert "the rig's reproducibility not known: the documented default" in result_report(alone)
    back = IdentificationResult.from_dict(alone.to_dict())
    assert back.reproducibility == DEFAULT
    history = pooled([[0.0170, 0.01705, 0.01695], [0.0125, 0.01254, 0.01246]], power=-2)  # above the default
    known = identify(trace, rig, Options(discover=False, reproducibility=history))
    assert known.uncertainty_budget["J"].u > alone.uncertainty_budget["J"].u
    assert known.J == alone.J
    assert "between releases" in result_report(known) and ": in u" in result_report(known)
    assert known.to_dict()["reproducibility"]["relative"] == pytest.approx(history.relative)


def test_a_release_counts_a_history_of_at_least_min_dof_and_the_default_otherwise():
    assert MIN_DOF == 2
    # one object released twice: ν = 1, too thin (a Type A line of ν = 1 setting u would set k near 13)
    assert for_release(pooled([[4.0, 4.004]])) is DEFAULT
    assert for_release(pooled([])) is DEFAULT and for_release(None) is DEFAULT
    three = pooled([[4.0, 4.004, 3.998]])
    assert for_release(three) is three and three.counted and three.dof == 2.0
    two_pairs = pooled([[4.0, 4.004], [6.0, 6.003]])
    assert for_release(two_pairs) is two_pairs and two_pairs.dof == 2.0


def test_the_history_wins_then_the_rigs_calibration_figure_then_the_default():
    history = pooled([[4.0, 4.004, 3.998]])
    rig = calibrated(0.002, 3.0, 3, 6)
    assert for_release(history, rig) is history
    # a history too thin (ν = 1) gives way to the rig's figure, and a figure too thin to the default
    assert for_release(pooled([[4.0, 4.004]]), rig) is rig and for_release(None, rig) is rig
    assert for_release(None, calibrated(0.002, 1.0, 1, 2)) is DEFAULT
    assert rig.source == RIG and rig.counted and rig.known and "its calibration's 6 releases of 3 references" in rig.note()
