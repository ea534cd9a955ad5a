"""Whole-record identification: accuracy and honest uncertainties."""

import math

import numpy as np
import pytest

from measurement import Options, Pendulum, Rig, Trace, identify, simulate_trace
from measurement.errors import TraceError
from measurement.reports import result_report

from .reference import reference_motion, sensor

K_SEED001 = 0.3651


def test_compound_friction_drag_example_identified_with_declared_coulomb_quadratic():
    # Data from the independent reference solver, with encoder-like noise.
    g, J, mu, m, S, K = 9.8, 1000.0, 0.01, 500.0, 1.0, 10.0
    rig = Rig(kind="compound", mass=m, com_distance=S, g=g, declared=("coulomb", "quadratic"))
    omega_n = math.sqrt(m * g * S / J)
    t = np.arange(0.0, 30.0, 0.01)
    theta = reference_motion("compound", omega_n, t, -0.5, coulomb=mu * m * g / J, quadratic=K / J)
    rng = np.random.default_rng(7)
    trace = Trace(t, sensor(rng, theta, 1e-4, bits=17), source="compound-friction-drag")
    r = identify(trace, rig, Options(discover=False))
    assert pytest.approx(J, rel=5e-4) == r.J
    assert r.damping["coulomb"]["mu"].value == pytest.approx(mu, rel=0.05)
    assert r.damping["quadratic"]["K"].value == pytest.approx(K, rel=0.05)
    assert r.effects == ("coulomb", "quadratic")


def _viscous_trace(seed: int, J: float = 0.0125, c: float = 1.5e-4):
    rig = Rig(kind="torsion", stiffness=K_SEED001)
    truth = Pendulum(rig, J, {"viscous": {"c": c}})
    return rig, simulate_trace(truth, theta0=0.2, duration=20, rate=200, noise_std=2e-4, quantisation_bits=17,
                               pre_trigger=0.2, seed=seed)


def test_viscous_torsion_J_within_0_02_percent_and_uncertainty_matches_scatter():
    J = 0.0125
    values: list[float] = []
    stds: list[float] = []
    for seed in range(20):
        rig, trace = _viscous_trace(seed, J)
        r = identify(trace, rig, Options(discover=False))
        assert r.J is not None and r.J_std is not None and pytest.approx(J, rel=2e-4) == r.J
        values.append(r.J)
        stds.append(r.J_std)
    scatter = float(np.std(values, ddof=1))
    ratio = float(np.mean(stds)) / scatter
    assert 0.5 < ratio < 2.0, f"stated J_std {np.mean(stds):.3g} vs scatter {scatter:.3g}"


def test_result_object_is_complete_and_serialisable():
    import json

    rig, trace = _viscous_trace(1)
    rig = Rig(kind="torsion", stiffness=K_SEED001, tare_inertia=4.5043e-3, declared=("viscous",))
    r = identify(trace, rig)
    d = json.loads(r.to_json())
    for key in ("J", "J_std", "omega_n", "effects", "added_effects", "damping", "residual_rms", "baseline", "flags",
                "noise_floor", "statistics", "damping_ratio", "offset", "J_object"):
        assert key in d, key
    for key in ("effects", "J", "omega_n", "residual_rms"):
        assert key in d["baseline"]
    for key in ("n", "dof", "chi2", "aic", "bic"):
        assert key in d["statistics"]
    assert d["J_object"] == pytest.approx(d["J"] - 4.5043e-3)
    assert d["damping"]["viscous"]["c"]["unit"] == "N·m·s/rad"
    assert d["damping_ratio"] == pytest.approx(1.5e-4 / 0.0125 / (2 * r.omega_n), rel=1e-3)
    assert "J" in result_report(r) and "kg·m²" in result_report(r)


def test_parallel_axis_transfer():
    rig, trace = _viscous_trace(2)
    doc = {"rig": {"kind": "torsion", "stiffness": K_SEED001, "tare_inertia": 4.5e-3},
           "object": {"mass": 12.0, "axis_offset": 0.01}, "model": {"declared": ["viscous"]}}
    r = identify(trace, Rig.from_dict(doc))
    assert r.J is not None and r.J_object_axis == pytest.approx(r.J - 4.5e-3 - 12.0 * 0.01**2)


def test_rig_without_constant_reports_omega_and_normalised_damping():
    _, trace = _viscous_trace(3)
    r = identify(trace, Rig(kind="torsion"))
    assert r.J is None and r.J_std is None
    assert r.omega_n == pytest.approx(math.sqrt(K_SEED001 / 0.0125), rel=1e-4)
    assert r.damping["viscous"]["c_per_J"].value == pytest.approx(1.5e-4 / 0.0125, rel=0.02)
    assert r.damping["viscous"]["c"].value is None


def test_too_few_swings_is_an_input_error():
    rig = Rig(kind="torsion", stiffness=K_SEED001)
    trace = simulate_trace(Pendulum(rig, 0.0125), theta0=0.2, duration=1.5, rate=200, seed=1)
    with pytest.raises(TraceError, match="swing"):
        identify(trace, rig)


def test_a_short_hold_before_the_release_is_found():
    """20 held samples, then the release: the hold's level must come from the hold, not from the first 50 samples."""
    rig = Rig(kind="torsion", stiffness=K_SEED001)
    truth = Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}})
    trace = simulate_trace(truth, theta0=0.25, duration=20, rate=200, noise_std=5e-5, quantisation_bits=17,
                           pre_trigger=0.1, seed=4)
    r = identify(trace, rig)
    assert r.window["release_detected"] and r.window["t_start"] >= 0.09
    assert r.added_effects == () and "unmodeled_residual" not in r.flags
    assert pytest.approx(0.0125, rel=2e-4) == r.J
