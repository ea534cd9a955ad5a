"""Gauge studies (Type 1, Gauge R&R by ANOVA) against the published worked examples, an independent
computation of the same figures, and the studies the module refuses."""

from __future__ import annotations

import json
import math
import statistics

import numpy as np
import pytest

from measurement.gauge import (
    ACCEPTABLE,
    APPRAISER,
    CG_LIMIT,
    CONDITIONAL,
    INTERACTION,
    NOT_ACCEPTABLE,
    PART,
    REPEATABILITY,
    TOTAL,
    BiasTest,
    GaugeRR,
    GaugeStudyError,
    Type1Study,
    bias_test,
    capability_warnings,
    gauge_rr,
    gauge_rr_records,
    grr_verdict,
    type1_study,
)
from measurement.spc import individuals, with_gauge

# Automotive Industry Action Group, "Measurement Systems Analysis — Reference Manual", 4th edition (2010),
# ch. III section B: the Gauge R&R data collection sheet of the worked example (appraisers A, B, C;
# 3 trials; parts 1 … 10), one row per appraiser and trial.
AIAG_SHEET = {
    "A": [[0.29, -0.56, 1.34, 0.47, -0.80, 0.02, 0.59, -0.31, 2.26, -1.36],
          [0.41, -0.68, 1.17, 0.50, -0.92, -0.11, 0.75, -0.20, 1.99, -1.25],
          [0.64, -0.58, 1.27, 0.64, -0.84, -0.21, 0.66, -0.17, 2.01, -1.31]],
    "B": [[0.08, -0.47, 1.19, 0.01, -0.56, -0.20, 0.47, -0.63, 1.80, -1.68],
          [0.25, -1.22, 0.94, 1.03, -1.20, 0.22, 0.55, 0.08, 2.12, -1.62],
          [0.07, -0.68, 1.34, 0.20, -1.28, 0.06, 0.83, -0.34, 2.19, -1.50]],
    "C": [[0.04, -1.38, 0.88, 0.14, -1.46, -0.29, 0.02, -0.46, 1.77, -1.49],
          [-0.11, -1.13, 1.09, 0.20, -1.07, -0.67, 0.01, -0.56, 1.45, -1.77],
          [-0.15, -0.96, 0.67, 0.11, -1.45, -0.49, 0.21, -0.49, 1.87, -2.16]],
}
# the same manual, ch. III section B, the bias study (independent sample method): 15 measurements of a
# part of reference value 6.00
AIAG_BIAS = [5.8, 5.7, 5.9, 5.9, 6.0, 6.1, 6.0, 6.1, 6.4, 6.3, 6.0, 6.1, 6.2, 5.6, 6.0]


def aiag_values() -> list[list[list[float]]]:
    """The sheet as values[part][appraiser][trial]."""
    return [[[AIAG_SHEET[a][t][p] for t in range(3)] for a in "ABC"] for p in range(10)]


def test_gauge_rr_reproduces_the_aiag_anova_table():
    """AIAG MSA 4th ed., ch. III-B, the ANOVA table of the worked example (Table III-B 4): SS to 4
    decimals, MS to 5, F to 2 (appraiser and part against the interaction, the interaction against
    repeatability: F 79.41, 492.29, 0.434)."""
    g = gauge_rr(aiag_values())
    rows = {r.source: r for r in g.anova}
    assert [r.source for r in g.anova] == [APPRAISER, PART, INTERACTION, REPEATABILITY, TOTAL]
    published = {APPRAISER: (2, 3.1673, 1.58363, 79.41), PART: (9, 88.3619, 9.81799, 492.29),
                 INTERACTION: (18, 0.3590, 0.01994, 0.434), REPEATABILITY: (60, 2.7589, 0.04598, None)}
    for source, (df, ss, ms, f) in published.items():
        row = rows[source]
        assert row.df == df and row.ss == pytest.approx(ss, abs=5e-5) and row.ms == pytest.approx(ms, abs=5e-6)
        if f is None:
            assert row.f is None
        else:
            assert row.f == pytest.approx(f, abs=5e-3 if f > 1 else 5e-4)
    assert rows[TOTAL].df == 89 and rows[TOTAL].ss == pytest.approx(94.6471, abs=5e-5)
    # the interaction is far from significant: pooled into repeatability, as the manual's figures are
    p_interaction = rows[INTERACTION].p
    assert p_interaction is not None and p_interaction > 0.25 and g.pooled
    assert g.anova_pooled is not None and g.anova_pooled[2].df == 78


def test_gauge_rr_reproduces_the_aiag_variance_components():
    """AIAG MSA 4th ed., ch. III-B, the ANOVA method's % variation and contribution (Table III-B 5):
    variances, σ, % of total variation, % contribution, ndc."""
    g = gauge_rr(aiag_values())
    published = [  # (σ, variance, σ to, % of TV, % contribution)
        (g.ev, 0.039973, 0.199933, 18.4, 3.4), (g.av, 0.051455, 0.226838, 20.9, 4.4), (g.interaction, 0.0, 0.0, 0.0, 0.0),
        (g.grr, 0.09143, 0.302373, 27.9, 7.8), (g.pv, 1.086446, 1.042327, 96.0, 92.2)]
    for sigma, var, sd, pct_tv, pct_contribution in published:
        assert sigma**2 == pytest.approx(var, abs=5e-6) and sigma == pytest.approx(sd, abs=5e-6)
        assert g.pct_of_process(sigma) == pytest.approx(pct_tv, abs=0.05)
        assert 100 * sigma**2 / g.tv**2 == pytest.approx(pct_contribution, abs=0.05)
    assert g.tv**2 == pytest.approx(1.177876, abs=5e-6) and g.tv == pytest.approx(1.085302, abs=5e-6)
    assert g.ndc == 4  # 1.41 · 1.04233 / 0.30237 = 4.86, floored
    assert g.verdict_process == CONDITIONAL and g.verdict_tolerance is None and g.pct_grr_tolerance is None


def test_bias_test_reproduces_the_aiag_bias_study():
    """AIAG MSA 4th ed., ch. III-B, the bias study's analysis (Tables III-B 1 and 2): mean 6.0067, σ_r
    0.2120, σ_b 0.0547, bias 0.0067, t 0.1224 with 14 degrees of freedom, 95 % interval −0.1107 …
    0.1241. The manual's t divides its rounded bias by its rounded σ_b (0.0067/0.0547); unrounded it is
    0.1218, hence the looser tolerance on t."""
    b = bias_test(AIAG_BIAS, 6.00)
    assert b.n == 15 and b.dof == 14 and b.mean == pytest.approx(6.0067, abs=5e-5)
    assert b.s == pytest.approx(0.2120, abs=5e-5) and b.se == pytest.approx(0.0547, abs=5e-5)
    assert b.bias == pytest.approx(0.0067, abs=5e-5) and b.t == pytest.approx(0.1224, abs=1e-3)
    assert b.ci == pytest.approx((-0.1107, 0.1241), abs=5e-5)
    assert not b.significant and b.p > 0.05
    # 15 values are a bias study, not a Type 1 study
    with pytest.raises(GaugeStudyError, match="at least 25"):
        type1_study(AIAG_BIAS, 6.00, tolerance=1.0)


def _type1_values(n: int = 50, bias: float = 0.0004, s: float = 0.001) -> list[float]:
    """n readings of a 2.5 reference: normal quantiles (mean exactly 2.5 + bias, spread close to s) in a
    shuffled order, so the figures do not hang on a random draw."""
    from scipy.stats import norm

    deviations = s * norm.ppf((np.arange(n) + 0.5) / n)
    return [float(v) for v in 2.5 + bias + np.random.default_rng(7).permutation(deviations)]


def test_type1_study_against_a_hand_computation():
    values = _type1_values()
    ref, T = 2.5, 0.05
    st = type1_study(values, ref, T, resolution=0.0001)
    mean, s = statistics.fmean(values), statistics.stdev(values)
    assert st.n == 50 and st.s == pytest.approx(s, rel=1e-12) and st.bias.bias == pytest.approx(mean - ref, rel=1e-12)
    assert st.cg == pytest.approx(0.2 * T / (6 * s), rel=1e-12)
    assert st.cgk == pytest.approx((0.1 * T - abs(mean - ref)) / (3 * s), rel=1e-12)
    # the smallest tolerances give Cg, Cgk = 1.33 exactly
    assert st.cg_at(st.min_tolerance_cg) == pytest.approx(CG_LIMIT) and st.cgk_at(st.min_tolerance_cgk) == pytest.approx(CG_LIMIT)
    assert st.min_tolerance_cg == pytest.approx(1.33 * 6 * s / 0.2) and st.min_tolerance_cgk > st.min_tolerance_cg
    # run chart: the values in order, the reference and ±10 % of the tolerance around it
    assert st.values == tuple(values) and (st.chart_lower, st.chart_upper) == pytest.approx((ref - 0.005, ref + 0.005))
    assert st.resolution_percent == pytest.approx(0.2) and st.capable == (st.cg >= 1.33 and st.cgk >= 1.33)
    # a bias of 0.4 s over 50 values is significant (t ≈ 2.8): the note says so
    assert st.bias.significant and any("bias differs" in n for n in st.notes)


def test_type1_notes_and_verdict():
    few = type1_study(_type1_values(30, bias=0.0), 2.5, 0.05, resolution=0.005)
    assert any("50 are recommended" in n for n in few.notes) and any("resolution is 10 %" in n for n in few.notes)
    narrow = type1_study(_type1_values(), 2.5, 0.02)
    assert narrow.cg < CG_LIMIT and not narrow.capable
    wide = type1_study(_type1_values(), 2.5, 0.2)
    assert wide.capable and wide.notes == (f"the bias differs from zero (p = {wide.bias.p:.3g}): correct the "
                                           "instrument's offset or its reference",)


@pytest.mark.parametrize(("values", "reference", "tolerance", "match"), [
    ([1.0] * 24 + [1.1], 1.0, 1.0, None),
    ([1.0] * 24, 1.0, 1.0, "at least 25"),
    ([1.0] * 30, 1.0, 1.0, "no scatter"),
    ([1.0, 1.1] * 15, 1.0, 0.0, "tolerance"),
    ([1.0, 1.1] * 15, 1.0, -1.0, "tolerance"),
    ([1.0, math.nan] * 15, 1.0, 1.0, "finite"),
    ([1.0, 1.1] * 15, math.inf, 1.0, "finite"),
])
def test_type1_refusals(values, reference, tolerance, match):
    if match is None:
        assert type1_study(values, reference, tolerance).n == 25
        return
    with pytest.raises(GaugeStudyError, match=match):
        type1_study(values, reference, tolerance)


def _sums_by_least_squares(x: np.ndarray) -> dict[str, float]:
    """The ANOVA sums of squares as differences of residual sums of nested linear models (dummy
    variables, numpy's least squares): an independent route to what the balanced-design formulas give."""
    p, a, r = x.shape
    y = x.reshape(-1)
    part = np.repeat(np.arange(p), a * r)
    appr = np.tile(np.repeat(np.arange(a), r), p)

    def rss(*columns: np.ndarray) -> float:
        X = np.column_stack([np.ones_like(y), *columns])
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        return float(np.sum((y - X @ beta) ** 2))

    P = np.stack([(part == i).astype(float) for i in range(1, p)], axis=1)
    A = np.stack([(appr == j).astype(float) for j in range(1, a)], axis=1)
    PA = np.stack([P[:, i] * A[:, j] for i in range(p - 1) for j in range(a - 1)], axis=1)
    total = float(np.sum((y - y.mean()) ** 2))
    return {PART: total - rss(P), APPRAISER: total - rss(A), INTERACTION: rss(P, A) - rss(P, A, PA),
            REPEATABILITY: rss(P, A, PA), TOTAL: total}


def test_anova_sums_match_a_least_squares_model_comparison():
    rng = np.random.default_rng(11)
    x = (rng.normal(0, 1, (8, 1, 1)) + rng.normal(0, 0.3, (1, 4, 1)) + rng.normal(0, 0.2, (8, 4, 1))
         + rng.normal(0, 0.1, (8, 4, 3)))
    g = gauge_rr(x.tolist())
    by_lstsq = _sums_by_least_squares(x)
    for row in g.anova:
        assert row.ss == pytest.approx(by_lstsq[row.source], rel=1e-9, abs=1e-12)


def test_variance_components_recover_a_simulated_gauge():
    """400 simulated studies of a gauge with known components (σ_P 1, σ_A 0.3, σ_AP 0.2, σ_E 0.1): the
    ANOVA estimates of the variances average to the truth (they are unbiased; 0.2 ≫ 0.1/√3 keeps the
    interaction significant, so neither pooling nor the floor at 0 bends them)."""
    rng = np.random.default_rng(2024)
    truth = {"pv": 1.0, "av": 0.3, "interaction": 0.2, "ev": 0.1}
    est: dict[str, list[float]] = {k: [] for k in truth}
    for _ in range(400):
        x = (rng.normal(0, 1.0, (10, 1, 1)) + rng.normal(0, 0.3, (1, 3, 1)) + rng.normal(0, 0.2, (10, 3, 1))
             + rng.normal(0, 0.1, (10, 3, 3)))
        g = gauge_rr(x.tolist(), pool_alpha=1.0)
        for k in truth:
            est[k].append(getattr(g, k) ** 2)
    for k, sigma in truth.items():
        mean, se = statistics.fmean(est[k]), statistics.stdev(est[k]) / math.sqrt(len(est[k]))
        assert abs(mean - sigma**2) < 4 * se, (k, mean, sigma**2, se)


def test_interaction_kept_when_pooling_is_off():
    # on the AIAG data with the interaction kept: EV² = MS_E, INT² = max(0, (MS_AP − MS_E)/r) = 0,
    # AV² = (MS_A − MS_AP)/(p·r), PV² = (MS_P − MS_AP)/(a·r)
    g = gauge_rr(aiag_values(), pool_alpha=1.0)
    ms = {r.source: r.ms for r in g.anova if r.ms is not None}
    assert not g.pooled and g.anova_pooled is None
    assert g.ev**2 == pytest.approx(ms[REPEATABILITY]) and g.interaction == 0.0
    assert g.av**2 == pytest.approx((ms[APPRAISER] - ms[INTERACTION]) / 30)
    assert g.pv**2 == pytest.approx((ms[PART] - ms[INTERACTION]) / 9)


def test_percent_of_tolerance_uses_six_sigma_and_records_group_like_the_array():
    g = gauge_rr(aiag_values(), tolerance=8.0)
    assert g.spread == 6.0 and g.pct_grr_tolerance == pytest.approx(100 * 6 * 0.302373 / 8.0, rel=1e-5)
    assert g.verdict_tolerance == CONDITIONAL
    old = gauge_rr(aiag_values(), tolerance=8.0, spread=5.15)
    assert old.pct_grr_tolerance is not None and g.pct_grr_tolerance is not None
    assert old.pct_grr_tolerance == pytest.approx(g.pct_grr_tolerance * 5.15 / 6)
    records = [(f"P{p + 1}", name, AIAG_SHEET[name][t][p]) for t in range(3) for name in "ABC" for p in range(10)]
    by_records = gauge_rr_records(records, tolerance=8.0)
    assert by_records.parts == tuple(f"P{p + 1}" for p in range(10)) and by_records.appraisers == ("A", "B", "C")
    assert by_records.grr == pytest.approx(g.grr) and by_records.values == g.values


@pytest.mark.parametrize(("percent", "verdict"), [(9.99, ACCEPTABLE), (10.0, CONDITIONAL), (30.0, CONDITIONAL),
                                                  (30.01, NOT_ACCEPTABLE)])
def test_verdict_bands(percent, verdict):
    assert grr_verdict(percent) == verdict


def _drop(values, part, appraiser):
    out = [[list(c) for c in p] for p in values]
    out[part][appraiser].pop()
    return out


@pytest.mark.parametrize(("values", "match"), [
    (lambda v: _drop(v, 3, 1), "part 4 appraiser 2: 2"),
    (lambda v: [p[:2] if i == 5 else p for i, p in enumerate(v)], "different numbers of appraisers"),
    (lambda v: [p[:1] for p in v], "at least 2 appraisers"),
    (lambda v: [[c[:1] for c in p] for p in v], "at least 2 trials"),
    (lambda v: v[:1], "at least 2 parts"),
    (lambda v: [[[1.0, 1.0] for _ in p] for p in v], "no repeatability"),
    (lambda v: [[[math.nan if (i, j) == (0, 0) else x for x in c] for j, c in enumerate(p)] for i, p in enumerate(v)],
     "finite"),
])
def test_gauge_rr_refusals(values, match):
    with pytest.raises(GaugeStudyError, match=match):
        gauge_rr(values(aiag_values()))


def test_gauge_rr_refuses_bad_settings_and_unbalanced_records():
    with pytest.raises(GaugeStudyError, match="tolerance"):
        gauge_rr(aiag_values(), tolerance=0.0)
    with pytest.raises(GaugeStudyError, match="labels"):
        gauge_rr(aiag_values(), appraisers=["A", "A", "B"])
    records = [(p, a, float(p + t)) for p in range(3) for a in "AB" for t in range(2)]
    with pytest.raises(GaugeStudyError, match="missing part 2 by C"):
        gauge_rr_records([*records, (0, "C", 0.0), (0, "C", 1.0), (1, "C", 1.0), (1, "C", 2.0)])
    with pytest.raises(GaugeStudyError, match="part 1 by B: 3"):
        gauge_rr_records([*records, (1, "B", 5.0)])


def test_results_round_trip_through_json():
    g = gauge_rr(aiag_values(), tolerance=8.0)
    back = GaugeRR.from_dict(json.loads(json.dumps(g.to_dict())))
    assert back == g and back.ndc == 4 and back.to_dict()["verdict_tolerance"] == CONDITIONAL
    st = type1_study(_type1_values(), 2.5, 0.05, resolution=0.0001)
    again = Type1Study.from_dict(json.loads(json.dumps(st.to_dict())))
    assert again == st and isinstance(again.bias, BiasTest) and again.to_dict()["capable"] == st.capable


def test_capability_warnings_name_the_failing_figure():
    g = gauge_rr(aiag_values())
    # ndc 4 < 5 always; %GRR of the tolerance 6·0.3024/5 = 36 % > 30 % only at the narrow tolerance
    wide = capability_warnings(grr=g, tolerance=20.0)
    assert [w.figure for w in wide] == ["ndc"] and "Cp, Cpk" in wide[0].message
    narrow = capability_warnings(grr=g, tolerance=5.0)
    assert [w.figure for w in narrow] == ["%GRR of the tolerance", "ndc"]
    assert narrow[0].value == pytest.approx(100 * 6 * g.grr / 5.0) and narrow[0].limit == 30.0
    st = type1_study(_type1_values(), 2.5, 0.2)
    assert capability_warnings(type1=st) == ()
    at_spec = capability_warnings(type1=st, tolerance=st.min_tolerance_cg * 0.9)
    assert [w.figure for w in at_spec] == ["Cg", "Cgk"] and at_spec[0].value == pytest.approx(1.33 * 0.9)


def test_spc_summary_carries_the_gauge_warnings():
    values = [10.0, 10.4, 9.8, 10.1, 10.3, 9.9, 10.2, 10.0]
    plain = individuals(values, lsl=8.0, usl=13.0)
    st = type1_study(_type1_values(n=50, bias=0.0, s=0.05), 2.5, 1.0)  # Cg 0.67 at T = 1, 3.3 at T = 5
    flagged = with_gauge(individuals(values, lsl=9.5, usl=10.5), type1=st)
    assert [w.figure for w in flagged.gauge_warnings] == ["Cg", "Cgk"]
    assert flagged.to_dict()["gauge_warnings"][0]["figure"] == "Cg" and "not meaningful" in flagged.report()
    assert with_gauge(plain, type1=st).gauge_warnings == ()
    # without limits there is no index to object to, and the published summary keeps its keys
    no_limits = with_gauge(individuals(values), type1=st)
    assert no_limits.gauge_warnings == () and "gauge_warnings" not in no_limits.to_dict()
    assert "gauge_warnings" not in plain.to_dict()
