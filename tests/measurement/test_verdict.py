"""The conformity decision (guard band per ISO 14253-1) and the combination of repeat releases, by hand."""

from __future__ import annotations

import math

import pytest

from measurement.verdict import (
    INVALID,
    NOK,
    OK,
    QualityRules,
    Reading,
    Specification,
    VerdictError,
    combine,
    decide,
    judge_release,
)
from tests.judged import judged

SPEC = Specification.symmetric("J", 0.0125, 0.0001)  # 0.0124 … 0.0126 kg·m², guard band, k = 2


def test_guard_band_proves_conformance_only_inside_the_zone_shrunk_by_U():
    # |x − nominal| + U = 0.00006 + 0.00002 ≤ 0.0001 → conformance proven
    d = decide(0.01256, 1e-5, SPEC)
    assert d.verdict == OK and d.zone == "conformance" and pytest.approx(2e-5) == d.U
    assert d.deviation == pytest.approx(6e-5)
    # inside the tolerance, but |x − nominal| + U = 0.00009 + 0.00002 > 0.0001: plain comparison says OK, the rule NOK
    d = decide(0.01259, 1e-5, SPEC)
    assert d.verdict == NOK and d.zone == "uncertainty" and "not proven" in d.reasons[0]
    assert decide(0.01259, 1e-5, Specification.symmetric("J", 0.0125, 0.0001, rule="simple")).verdict == OK
    # the recipe may ask for a re-measurement instead
    assert decide(0.01259, 1e-5, Specification.symmetric("J", 0.0125, 0.0001, uncertain=INVALID)).verdict == INVALID
    # |x − nominal| − U > T: nonconformance proven
    d = decide(0.01263, 1e-5, SPEC)
    assert d.verdict == NOK and d.zone == "nonconformance" and "above the upper limit" in d.reasons[0]
    assert decide(0.01237, 1e-5, SPEC).reasons[0].count("below the lower limit") == 1


def test_specification_errors_say_what_was_expected():
    with pytest.raises(VerdictError, match="tolerance must be > 0"):
        Specification.symmetric("J", 0.0125, -1.0)
    with pytest.raises(VerdictError, match="quantity must be one of"):
        Specification.symmetric("mass", 0.0125, 1e-4)
    with pytest.raises(VerdictError, match="lower <= nominal <= upper"):
        Specification("J", 0.02, 0.01, 0.015)


def test_a_release_is_invalid_for_a_recipe_flag_a_large_std_or_too_few_swings():
    rules = QualityRules(max_std=5e-6, min_swings=3)
    assert judge_release(Reading(0.0125, 1e-6, 0.0, (), 20.0), SPEC, rules).verdict == OK
    d = judge_release(Reading(0.0125, 1e-6, 0.0, ("fit_not_converged", "outliers_removed"), 20.0), SPEC, rules)
    assert d.verdict == INVALID and d.reasons == ("flag fit_not_converged",)
    # a flag that describes the residual invalidates nothing by default; a recipe may name it
    described = Reading(0.0125, 1e-6, 0.0, ("unmodeled_residual", "halves_disagree", "model_ambiguous"), 20.0)
    assert judge_release(described, SPEC, rules).verdict == OK
    strict = QualityRules(invalid_flags=("unmodeled_residual",))
    assert judge_release(described, SPEC, strict).reasons == ("flag unmodeled_residual",)
    d = judge_release(Reading(0.0125, 6e-6, 0.0, (), 20.0), SPEC, rules)
    assert d.verdict == INVALID and "above the limit" in d.reasons[0]
    d = judge_release(Reading(0.0125, 1e-6, 0.0, (), 2.5), SPEC, rules)
    assert d.verdict == INVALID and "2.5 swings" in d.reasons[0]
    assert judge_release(Reading(None, None), SPEC, rules).verdict == INVALID


def test_reading_takes_the_random_and_systematic_parts_of_its_quantitys_budget():
    result = judged({"J": 0.0170, "J_object": 0.0125}, 3e-6, 5e-6, flags=("calibration_due",), coverage_factor=2.2,
                    omega_n=4.6, window={"t_start": 0.1, "t_stop": 10.1})
    r = Reading.from_result(result, "J_object")
    assert (r.value, r.u_random, r.u_systematic, r.coverage_factor) == (0.0125, 3e-6, 5e-6, 2.2)
    assert r.swings == pytest.approx(4.6 * 10 / (2 * math.pi)) and r.flags == ("calibration_due",)
    assert Reading.from_result(result, "J").value == 0.0170
    # no value (a rig without an [object]), or a value without a budget: nothing a verdict can use
    assert Reading.from_result(result, "J_object_axis").value is None
    unbudgeted = Reading.from_result(judged({}, 1e-6, J=0.017), "J")
    assert unbudgeted.value == 0.017 and unbudgeted.u_random is None
    assert judge_release(unbudgeted, SPEC, QualityRules()).verdict == INVALID


def test_three_agreeing_releases_combine_with_type_a_std_of_the_mean():
    vals = [0.012500, 0.012502, 0.012498]
    part = combine([Reading(v, 1e-6, 2e-6) for v in vals], SPEC, QualityRules())
    s = math.sqrt(sum((v - 0.0125) ** 2 for v in vals) / 2)  # 2e-6
    assert part.mean == pytest.approx(0.0125) and part.std == pytest.approx(s)
    assert part.u_typeA == pytest.approx(s / math.sqrt(3))
    assert part.u_fit == pytest.approx(math.sqrt(3) * 1e-6 / 3)
    # the larger random estimate (Type A here) with the common calibration part in quadrature, once
    assert part.decision.u_c == pytest.approx(math.hypot(s / math.sqrt(3), 2e-6))
    assert part.verdict == OK and part.used == (0, 1, 2) and part.excluded == ()


def test_a_release_that_disagrees_is_excluded_and_reported():
    readings = [Reading(0.012500, 1e-6), Reading(0.012501, 1e-6), Reading(0.012530, 1e-6)]
    part = combine(readings, SPEC, QualityRules(consistency_limit=3))
    assert part.used == (0, 1) and part.excluded[0]["index"] == 2
    assert "disagrees with the other releases" in part.excluded[0]["reason"]
    assert part.mean == pytest.approx(0.0125005) and part.verdict == OK


def test_two_disagreeing_releases_make_the_part_invalid():
    part = combine([Reading(0.012500, 1e-6), Reading(0.012530, 1e-6)], SPEC, QualityRules())
    assert part.verdict == INVALID and "disagree" in part.decision.reasons[0]


def test_invalid_releases_are_excluded_and_too_few_usable_make_the_part_invalid():
    readings = [Reading(0.0125, 1e-6, flags=("fit_not_converged",)), Reading(0.012501, 1e-6),
                Reading(0.012499, 1e-6)]
    part = combine(readings, SPEC, QualityRules(min_valid_releases=2))
    assert part.verdict == OK and part.used == (1, 2)
    assert part.excluded == ({"index": 0, "reason": "invalid: flag fit_not_converged"},)
    part = combine(readings, SPEC, QualityRules(min_valid_releases=3))
    assert part.verdict == INVALID and "2 usable of 3 releases" in part.decision.reasons[0]
    every = [Reading(0.0125, 1e-6, flags=("fit_not_converged",))] * 3
    assert combine(every, SPEC, QualityRules()).verdict == INVALID


def test_a_release_whose_model_does_not_hold_counts_for_less():
    # the release's model-form term joins its fit σ as random; the part weighs each release by it
    held = judged({"J": 0.012500}, 1e-6)
    loose = judged({"J": 0.012508}, math.hypot(1e-6, 8e-6), flags=("halves_disagree",))
    r = Reading.from_result(loose, "J")
    assert r.u_random == pytest.approx(math.hypot(1e-6, 8e-6))
    part = combine([Reading.from_result(held, "J"), r], SPEC, QualityRules())
    w = 1 / 1e-12, 1 / (65e-12)
    assert part.mean == pytest.approx((w[0] * 0.0125 + w[1] * 0.012508) / sum(w))
    assert part.u_fit == pytest.approx(1 / math.sqrt(sum(w)))


def test_the_part_value_is_the_joint_identification_of_its_usable_releases():
    readings = [Reading(0.012500, 1e-6), Reading(0.012502, 1e-6, flags=("fit_not_converged",)), Reading(0.012501, 1e-6)]
    asked = []

    def joint_of(used):
        asked.append(tuple(used))
        return 0.0125004, 4e-7, {"consistency": {"p": 0.6}}

    part = combine(readings, SPEC, QualityRules(min_valid_releases=2), joint_of)
    assert asked == [(0, 2)]  # the invalid release is left out of the joint identification
    assert part.mean == 0.0125004 and part.u_fit == 4e-7 and part.joint == {"consistency": {"p": 0.6}}
    assert part.to_dict()["joint"]["consistency"]["p"] == 0.6
    # without it (no identifications at hand) the weighted mean, as before
    assert combine(readings, SPEC, QualityRules(min_valid_releases=2)).joint is None


def test_a_joint_part_takes_its_own_k_not_the_one_a_release_owes_to_its_reproducibility_line():
    # each release's k is 2.86: its budget holds the rig's reproducibility with ν = 4 (Welch–Satterthwaite); the
    # joint u does not hold that line, so its k is the part's own (the specification's here)
    readings = [Reading(0.012500 + d, 1e-6, coverage_factor=2.86) for d in (0.0, 1e-7, -1e-7)]
    joint = combine(readings, SPEC, QualityRules(), lambda used: (0.0125, 5e-7, {"consistency": {"p": 0.9}}))
    assert joint.decision.u_c is not None and pytest.approx(2.0 * joint.decision.u_c) == joint.decision.U
    mean = combine(readings, SPEC, QualityRules())
    assert mean.decision.u_c is not None and pytest.approx(2.86 * mean.decision.u_c) == mean.decision.U
