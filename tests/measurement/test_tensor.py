"""The inertia tensor from a multi-orientation set: recovery, principal axes, checks, conventions, the plan."""

from __future__ import annotations

import math

import numpy as np
import pytest

from measurement import flags as F
from measurement import identify
from measurement import tensor as TS
from measurement.errors import TensorError
from measurement.reports import tensor_report
from measurement.rig import Rig
from measurement.simulate import BRACKET, RigidBody, simulate_set
from measurement.tensor import Orientation, TensorPlan
from measurement.tensor_inputs import AxisReading, RigShared, axis_reading
from tests.judged import judged

#: the truth: the example bracket (products of inertia of both signs, principal moments well apart)
TRUTH = np.array(BRACKET.tensor)
MASS = BRACKET.mass
RIG = Rig(kind="torsion", stiffness=0.3651, tare_inertia=4.5e-3, declared=("viscous",))
#: the centre of mass off the swing axis for some orientations (m, part frame)
OFFSETS = {"x": (0.0, 0.03, -0.02), "xz": (0.01, 0.025, 0.0), "x-y-z": (0.02, -0.01, 0.015)}


def simulated_results(plan: TensorPlan, body: RigidBody, seed: int, mounted_axes=None):
    """Each orientation's release identified from a simulated trace of ``body`` on RIG."""
    sets = simulate_set(body, RIG, plan, seed=seed, mounted_axes=mounted_axes)
    return [[identify(trace, RIG) for trace in traces] for traces in sets]


def plan_with_offsets(axes, convention="negative"):
    return TensorPlan(tuple(Orientation(n, a, OFFSETS.get(n), 2e-5 if n in OFFSETS else 0.0) for n, a in axes),
                      part="bracket", mass=MASS, mass_std=1e-4, poi_convention=convention)


BODY = BRACKET


@pytest.fixture(scope="module")
def default_set():
    plan = plan_with_offsets(TS.DEFAULT_AXES)
    return plan, simulated_results(plan, BODY, seed=6)


@pytest.fixture(scope="module")
def nine_set():
    plan = plan_with_offsets(TS.NINE_AXES)
    return plan, simulated_results(plan, BODY, seed=5)


def z_scores(result, truth=TRUTH):
    sigma = np.sqrt(np.diag(result.cov)) * TS.convention_signs(result.poi_convention) ** 2
    return (TS.entries_of(result.tensor) - TS.entries_of(truth)) / sigma


@pytest.mark.parametrize("which", ["default_set", "nine_set"])
def test_a_known_tensor_is_recovered_within_2_sigma_per_component(which, request):
    plan, results = request.getfixturevalue(which)
    result = TS.solve_results(plan, results, RIG)
    z = z_scores(result)
    assert np.all(np.abs(z) <= 2.0), dict(zip(TS.COMPONENTS, z.round(2)))
    assert result.flags == ()
    assert result.dof == len(plan.orientations) - 6
    if result.dof:
        assert result.chi2_limit is not None and result.chi2 < result.chi2_limit
    # the reported U is k·σ of each component
    for c, s in zip(TS.COMPONENTS, np.sqrt(np.diag(result.cov))):
        assert result.U[c] == pytest.approx(2 * s)


def test_the_offsets_matter_so_the_parallel_axis_step_is_tested(default_set, monkeypatch):
    """Removing the parallel-axis term, or flipping its sign, moves the tensor far outside its uncertainty."""
    plan, results = default_set
    right = TS.solve_results(plan, results, RIG)
    assert np.all(np.abs(z_scores(right)) <= 2.0)
    true_term = TS.axis_offset_inertia
    for broken in (lambda m, n, d: 0.0, lambda m, n, d: -true_term(m, n, d)):
        monkeypatch.setattr(TS, "axis_offset_inertia", broken)
        wrong = TS.solve_results(plan, results, RIG)
        # far outside (each orientation's u holds the documented scatter between releases, 0.1 % of ω_n)
        assert np.max(np.abs(z_scores(wrong))) > 20
    monkeypatch.setattr(TS, "axis_offset_inertia", true_term)


def test_the_parallel_axis_term_is_the_mass_times_the_squared_distance_of_the_centre_of_mass_from_the_axis():
    rng = np.random.default_rng(1)
    masses = rng.uniform(0.1, 1.0, 7)
    points = rng.normal(0.0, 0.05, (7, 3))
    body = RigidBody.from_point_masses(masses, points)
    com = masses @ points / masses.sum()
    for _ in range(5):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        p = rng.normal(0.0, 0.1, 3)  # a point of the swing axis
        direct = sum(m * np.linalg.norm(np.cross(r - p, n)) ** 2 for m, r in zip(masses, points))
        assert body.inertia_about(n, p - com) == pytest.approx(direct, rel=1e-12)
        about_com = body.inertia_about(n)
        assert about_com + TS.axis_offset_inertia(body.mass, n, com - p) == pytest.approx(direct, rel=1e-12)


def test_principal_axes_match_the_truth_within_their_stated_angle(nine_set):
    plan, results = nine_set
    result = TS.solve_results(plan, results, RIG)
    lam, vec = np.linalg.eigh(TRUTH)
    for k in range(3):
        est = np.array(result.principal_axes[k])
        angle = math.degrees(math.acos(min(1.0, abs(float(est @ vec[:, k])))))
        assert angle <= result.principal_axes_U_deg[k], (k, angle, result.principal_axes_U_deg)
        assert abs(result.principal_moments[k] - lam[k]) <= result.principal_moments_U[k]
    axes = np.array(result.principal_axes)
    assert np.allclose(axes @ axes.T, np.eye(3), atol=1e-12) and np.linalg.det(axes) == pytest.approx(1.0)


def test_a_mistyped_axis_raises_tensor_inconsistent_naming_it():
    plan = plan_with_offsets(TS.NINE_AXES)
    s = 1 / math.sqrt(2)
    # the plan says the xy bisector; the part was mounted on the other one (a sign typed wrongly)
    results = simulated_results(plan, BODY, seed=7, mounted_axes={"xy": (s, -s, 0.0)})
    result = TS.solve_results(plan, results, RIG)
    assert F.TENSOR_INCONSISTENT in result.flags
    assert "'xy'" in result.reasons[F.TENSOR_INCONSISTENT]
    worst = max((o for o in result.orientations), key=lambda o: abs(o["normalised_residual"]))
    assert worst["name"] == "xy"


def test_both_conventions_round_trip():
    for conv in TS.CONVENTIONS:
        comps = TS.components_of(TRUTH, conv)
        assert np.array_equal(TS.matrix_from_components(comps, conv), TRUTH)
    neg, pos = TS.components_of(TRUTH, "negative"), TS.components_of(TRUTH, "positive")
    assert neg["Ixy"] == TRUTH[0, 1] == -pos["Ixy"] and neg["Ixx"] == pos["Ixx"]
    # a solve in either convention gives the same physical tensor; the products' signs follow the convention
    values = [float(TS.design_row(a) @ TS.entries_of(TRUTH)) for _, a in TS.DEFAULT_AXES]
    readings = [AxisReading(v, 1e-6) for v in values]
    a = TS.solve(TensorPlan.default(poi_convention="negative"), readings)
    b = TS.solve(TensorPlan.default(poi_convention="positive"), readings)
    assert np.allclose(a.tensor, TRUTH) and np.allclose(b.tensor, TRUTH)
    assert b.components["Ixy"] == pytest.approx(-a.components["Ixy"]) == pytest.approx(1.5e-3)
    assert np.allclose(TS.matrix_from_components(b.components, "positive"), a.tensor)
    # the covariance of a diagonal and a product changes sign with the convention
    assert b.cov[0, 3] == pytest.approx(-a.cov[0, 3]) and a.cov[0, 3] != 0


def exact_readings(plan, truth=TRUTH, u=1e-6):
    return [AxisReading(float(TS.design_row(o.axis) @ TS.entries_of(truth)), u) for o in plan.orientations]


def test_an_invalid_orientation_is_excluded_and_named():
    plan = TensorPlan.nine()
    readings = exact_readings(plan)
    readings[7] = AxisReading(None, None, invalid="flag unmodeled_residual")
    result = TS.solve(plan, readings)
    assert F.ORIENTATION_EXCLUDED in result.flags and "x-y-z" in result.reasons[F.ORIENTATION_EXCLUDED]
    assert result.dof == 2 and np.allclose(result.tensor, TRUTH)
    assert result.orientations[7]["excluded"] == "flag unmodeled_residual"
    # with the default six, none can be spared
    six = TensorPlan.default()
    readings = exact_readings(six)
    readings[3] = None
    with pytest.raises(TensorError, match="cannot determine"):
        TS.solve(six, readings)


def test_an_invalid_release_is_excluded_by_the_release_pooling():
    shared = RigShared(tare=4.5e-3)
    good = judged({"J": 0.0165, "J_object": 0.012}, 1e-6)
    bad = judged({"J": 0.0165, "J_object": 0.013}, 1e-6, flags=(F.FIT_NOT_CONVERGED,))
    r = axis_reading([good, bad, good], shared)
    assert r.value == pytest.approx(0.012) and r.used == (0, 2) and r.excluded[0]["index"] == 1
    r = axis_reading([bad], shared)
    assert r.invalid and "fit_not_converged" in r.invalid


def test_a_release_counts_with_the_whole_u_of_its_budget():
    shared = RigShared(tare=4.5e-3)
    plain = judged({"J": 0.0165, "J_object": 0.012}, 1e-6)
    with_systematic = judged({"J": 0.0165, "J_object": 0.012}, 1e-6, math.sqrt(15) * 1e-6)
    assert axis_reading([plain], shared).u == pytest.approx(1e-6)
    assert axis_reading([with_systematic], shared).u == pytest.approx(4e-6)


def test_an_unphysical_tensor_is_flagged():
    fake = np.diag([0.001, 0.002, 0.005])  # I1 + I2 < I3: no body has it
    result = TS.solve(TensorPlan.default(), exact_readings(TensorPlan.default(), fake))
    assert F.TENSOR_UNPHYSICAL in result.flags and "triangle" in result.reasons[F.TENSOR_UNPHYSICAL]
    thin_rod = np.diag([1e-9, 0.004, 0.004])  # on the boundary, within its uncertainty: not flagged
    assert F.TENSOR_UNPHYSICAL not in TS.solve(TensorPlan.default(), exact_readings(TensorPlan.default(), thin_rod)).flags


def test_shared_rig_uncertainties_enter_the_covariance_but_not_chi2():
    plan = TensorPlan.nine()
    readings = [AxisReading(r.value, r.u, rig_inertia=r.value + 4.5e-3) for r in exact_readings(plan)]
    alone = TS.solve(plan, readings)
    shared = TS.solve(plan, readings, RigShared(scale_rel=1e-3, tare=4.5e-3, tare_std=2e-6))
    assert np.all(np.diag(shared.cov) > np.diag(alone.cov))
    # a stiffness error scales every J alike: the tensor scales, the set stays consistent
    scaled = [AxisReading(r.value * 1.002 + 4.5e-3 * 0.002, r.u, r.rig_inertia) for r in readings if r.value is not None]
    assert len(scaled) == len(readings)
    assert TS.solve(plan, scaled, RigShared(scale_rel=1e-3, tare=4.5e-3)).flags == ()


@pytest.mark.parametrize(("doc", "message"), [
    ({"orientation": [{"axis": [1, 0, 0]}] * 5}, "at least 6"),
    ({"orientation": [{"axis": a} for _, a in TS.DEFAULT_AXES[:5]] + [{"axis": [0, 0, 0]}]}, "zero vector"),
    ({"orientation": [{"axis": [math.cos(t), math.sin(t), 0]} for t in np.linspace(0, 3, 7)]}, "rank"),
    ({"orientation": [{"axis": a, "offset": [0.01, 0, 0]} for _, a in TS.DEFAULT_AXES]}, "no mass"),
    ({"part": {"poi_convention": "plus"}, "orientation": [{"axis": a} for _, a in TS.DEFAULT_AXES]}, "poi_convention"),
    ({"orientation": [{"axis": [1, 0]}] * 6}, "three numbers"),
    ({"orientation": [{"axis": a, "spin": 1} for _, a in TS.DEFAULT_AXES]}, "unknown key"),
    ({"orientation": [{"axis": a, "name": "same"} for _, a in TS.DEFAULT_AXES]}, "differ"),
])
def test_a_plan_that_cannot_determine_the_tensor_is_refused(doc, message):
    with pytest.raises(TensorError, match=message):
        TensorPlan.from_dict(doc)


def test_the_plan_reports_its_condition_number_and_normalises_axes():
    plan = TensorPlan.from_dict({"orientation": [{"axis": [2 * v for v in a]} for _, a in TS.DEFAULT_AXES]})
    assert np.allclose([np.linalg.norm(o.axis) for o in plan.orientations], 1.0)
    assert plan.condition_number == pytest.approx(TensorPlan.default().condition_number)
    assert 1 < plan.condition_number < 10
    assert [o.name for o in plan.orientations] == [f"o{i}" for i in range(1, 7)]


def test_the_result_is_plain_json():
    import json

    result = TS.solve(TensorPlan.default(), exact_readings(TensorPlan.default()))
    d = json.loads(result.to_json())
    for key in ("tensor", "tensor_cov", "tensor_U", "principal_moments", "principal_moments_U", "principal_axes",
                "principal_axes_U_deg", "poi_convention", "condition_number", "chi2", "dof", "orientations", "flags"):
        assert key in d, key
    assert len(d["tensor_cov"]) == 6 and set(d["tensor_U"]) == set(TS.COMPONENTS)
    assert {"axis", "J", "u", "fitted", "normalised_residual"} <= set(d["orientations"][0])
    assert "Ixy" in tensor_report(result)
