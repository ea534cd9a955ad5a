"""SPC numbers against hand computation on known series (Montgomery's constants)."""

from __future__ import annotations

import math

import pytest

from measurement.spc import SpcError, chart_constants, individuals, run_rules, xbar_r


def test_individuals_chart_by_hand():
    s = individuals([10, 12, 11, 13, 12], lsl=8, usl=16)
    # x̄ = 58/5; moving ranges 2, 1, 2, 1 → MR̄ = 1.5; σ = MR̄/1.128
    sigma = 1.5 / 1.128
    assert s.chart == "I-MR" and s.mean == pytest.approx(11.6) and s.range_mean == pytest.approx(1.5)
    assert s.sigma_within == pytest.approx(sigma)
    assert s.ucl == pytest.approx(11.6 + 3 * sigma) and s.lcl == pytest.approx(11.6 - 3 * sigma)
    assert s.range_ucl == pytest.approx(3.267 * 1.5, rel=1e-3) and s.range_lcl == 0
    assert s.cp == pytest.approx(8 / (6 * sigma)) and s.cpk == pytest.approx(3.6 / (3 * sigma))
    # overall σ: Σ(x − x̄)² = 5.2 over 4 degrees of freedom
    assert s.sigma_overall == pytest.approx(math.sqrt(1.3))
    assert s.pp == pytest.approx(8 / (6 * math.sqrt(1.3))) and s.ppk == pytest.approx(3.6 / (3 * math.sqrt(1.3)))
    assert s.outside == () and s.in_control
    assert s.cp == pytest.approx(1.00267, abs=1e-5) and s.cpk == pytest.approx(0.90240, abs=1e-5)


def test_xbar_r_chart_by_hand():
    s = xbar_r([[10, 11, 12], [11, 13, 12], [12, 12, 15]], lsl=9, usl=15)
    # means 11, 12, 13 → X̿ = 12; ranges 2, 2, 3 → R̄ = 7/3; n = 3: A2 = 1.023, D4 = 2.574, d2 = 1.693
    rbar = 7 / 3
    assert s.chart == "Xbar-R" and s.subgroup == 3 and s.points == (11, 12, 13)
    assert s.mean == pytest.approx(12) and s.range_mean == pytest.approx(rbar)
    assert s.ucl == pytest.approx(12 + 1.023 * rbar, rel=1e-4) and s.lcl == pytest.approx(12 - 1.023 * rbar, rel=1e-4)
    assert s.range_ucl == pytest.approx(2.574 * rbar, rel=1e-3) and s.range_lcl == 0
    assert s.sigma_within == pytest.approx(rbar / 1.693)
    assert s.cp == pytest.approx(6 / (6 * rbar / 1.693)) and s.cpk == pytest.approx(3 / (3 * rbar / 1.693))


def test_points_outside_and_run_rules():
    s = individuals([10, 10.2, 9.9, 10.1, 10.0, 9.8, 10.1, 14.0])
    # MR̄ = 5.2/7, UCL = x̄ + 3·MR̄/1.128 = 12.488: the last point is outside
    assert s.ucl == pytest.approx(84.1 / 8 + 3 * (5.2 / 7) / 1.128) and s.outside == (7,)
    assert ("beyond_limits", 7) in [(v.rule, v.index) for v in s.violations]
    run = run_rules([1] * 8 + [-8], centre=0.0, sigma=10.0)
    assert [(v.rule, v.index) for v in run] == [("run_of_8", 7)]
    trend = run_rules([1, 2, 3, 4, 5, 6, 0], centre=3.5, sigma=100.0)
    assert [(v.rule, v.index) for v in trend] == [("trend_of_6", 5)]
    two = run_rules([0, 2.5, 0.5, 2.2], centre=0.0, sigma=1.0)
    assert [(v.rule, v.index) for v in two] == [("2_of_3_beyond_2sigma", 3)]


def test_constants_and_errors():
    c = chart_constants(5)
    assert c["A2"] == pytest.approx(0.577, abs=1e-3) and c["D4"] == pytest.approx(2.114, abs=2e-3)
    assert chart_constants(7)["D3"] == pytest.approx(0.076, abs=2e-3)
    with pytest.raises(SpcError, match="at least 2"):
        individuals([1.0])
    with pytest.raises(SpcError, match="one size"):
        xbar_r([[1, 2], [1, 2, 3]])
    with pytest.raises(SpcError, match="2 to 10"):
        chart_constants(11)
