"""The discovery loop on data with effects nobody declared.

Data come from the independent reference solver (tests/measurement/reference.py),
not from the simulator the fit uses, with realistic noise and a 17-bit encoder.
"""

import datetime as dt
import math
from dataclasses import replace

import numpy as np
import pytest

from measurement import Rig, Trace, identify
from measurement.rig import CalibrationRecord

from .reference import reference_motion, sensor

K = 0.3651
J = 0.0125
W = math.sqrt(K / J)
NOISE = 1e-4
T = np.arange(0.0, 30.0, 1 / 200)


def torsion_trace(seed=1, theta0=0.25, extra=None, t=T, **effects):
    theta = reference_motion("torsion", W, t, theta0, extra=extra, **effects)
    return Trace(t, sensor(np.random.default_rng(seed), theta, NOISE), source="reference")


def torsion_rig(declared=("viscous",)):
    return Rig(kind="torsion", stiffness=K, declared=declared)


def rms_vs_noise(r):
    return r.residual_rms / math.sqrt(NOISE**2 + (2 * math.pi / 2**17) ** 2 / 12)


def test_coulomb_friction_is_discovered():
    r = identify(torsion_trace(viscous=0.008, coulomb=0.012), torsion_rig())
    assert r.added_effects == ("coulomb",)
    assert pytest.approx(J, rel=1e-3) == r.J
    assert abs(rms_vs_noise(r) - 1) < 0.2
    assert r.residual_rms < r.baseline.residual_rms
    assert "unmodeled_residual" not in r.flags
    step = r.steps[0]
    assert step.chosen == "coulomb" and "constant part" in step.evidence


def test_air_drag_is_discovered():
    r = identify(torsion_trace(viscous=0.005, quadratic=0.15), torsion_rig())
    assert r.added_effects == ("quadratic",)
    assert pytest.approx(J, rel=1e-3) == r.J
    assert abs(rms_vs_noise(r) - 1) < 0.2


def test_hardening_spring_is_discovered_and_fixes_J():
    k3_per_J = 40.0
    trace = torsion_trace(viscous=0.01, cubic=k3_per_J)
    # K is the spring's small-swing stiffness: a calibration read at zero amplitude (J takes ω there too)
    r = identify(trace, replace(torsion_rig(), calibration=CalibrationRecord(dt.date(2026, 1, 5), amplitude=0.0)))
    assert r.omega_n_read_at.amplitude == 0.0 and r.omega_n_read_at.basis == "calibration"
    assert r.baseline.J is not None
    assert abs(r.baseline.J / J - 1) > 3e-3, "the case must matter: viscous-only J off by > 0.3 %"
    assert r.added_effects == ("cubic_stiffness",)
    assert pytest.approx(J, rel=1e-3) == r.J
    assert r.stiffness["cubic_stiffness"]["k3"].value == pytest.approx(k3_per_J * J, rel=0.02)


def test_compound_rig_with_undeclared_viscous_damping():
    g, m, S, inertia = 9.8, 500.0, 1.0, 1000.0
    w = math.sqrt(m * g * S / inertia)
    t = np.arange(0.0, 30.0, 0.01)
    theta = reference_motion("compound", w, t, -0.5, coulomb=0.049, quadratic=0.01, viscous=0.03)
    trace = Trace(t, sensor(np.random.default_rng(3), theta, NOISE), source="reference")
    rig = Rig(kind="compound", mass=m, com_distance=S, g=g, declared=("coulomb", "quadratic"))
    r = identify(trace, rig)
    assert r.added_effects == ("viscous",)
    assert pytest.approx(inertia, rel=1e-3) == r.J


def test_sensor_zero_drift_is_discovered():
    rate = 3e-4  # rad/s
    r = identify(torsion_trace(viscous=0.01, extra=lambda t: rate * t), torsion_rig())
    assert r.added_effects == ("drift",)
    assert r.sensor["drift"]["rate"].value == pytest.approx(rate, rel=0.02)
    assert pytest.approx(J, rel=1e-3) == r.J


def test_no_false_discovery_on_clean_viscous_traces():
    t = np.arange(0.0, 20.0, 1 / 200)
    added = []
    for seed in range(20):
        r = identify(torsion_trace(seed=seed, viscous=0.012, t=t), torsion_rig())
        added.append(r.added_effects)
        assert pytest.approx(J, rel=2e-4) == r.J
        assert "unmodeled_residual" not in r.flags
    assert all(a == () for a in added), added


def test_effect_outside_the_library_is_flagged_not_forced():
    # a second, faster mode of small amplitude: no library effect explains it
    second = lambda t: 2e-3 * np.exp(-0.3 * t) * np.sin(2 * math.pi * 13.7 * t)  # noqa: E731
    r = identify(torsion_trace(viscous=0.01, extra=second), torsion_rig())
    assert "unmodeled_residual" in r.flags
    assert "outliers_removed" not in r.flags  # the structure's peaks are not glitches
    assert r.added_effects == ()
    assert pytest.approx(J, rel=3e-3) == r.J
    assert any("13.7" in line or "13.6" in line or "13.8" in line for line in r.structure), r.structure


def test_glitches_are_removed_and_flagged():
    trace = torsion_trace(viscous=0.01)
    y = trace.angle.copy()
    rng = np.random.default_rng(5)
    idx = rng.choice(np.arange(100, y.size - 100), 8, replace=False)
    y[idx] += rng.choice([-1, 1], 8) * 0.05
    r = identify(Trace(trace.t, y, source="glitchy"), torsion_rig())
    assert "outliers_removed" in r.flags
    assert r.window["n_outliers"] >= 8
    assert pytest.approx(J, rel=2e-4) == r.J
    assert r.added_effects == ()


def test_record_is_trimmed_to_the_swing():
    # 1 s held before the release, then a swing stopped by friction (at ~14 s), then at rest
    t = np.arange(0.0, 40.0, 1 / 200)
    release = 1.0
    theta = np.full(t.size, 0.25)
    moving = t >= release
    theta[moving] = reference_motion("torsion", W, t[moving] - release, 0.25, viscous=0.02, coulomb=0.15)
    trace = Trace(t, sensor(np.random.default_rng(2), theta, NOISE), source="trimmed")
    r = identify(trace, torsion_rig(("viscous", "coulomb")))
    assert r.window["release_detected"] and r.window["came_to_rest"]
    assert release - 0.02 <= r.window["t_start"] <= release + 0.02
    assert r.window["t_stop"] < 16.0
    assert pytest.approx(J, rel=2e-4) == r.J


def test_uneven_timestamps_are_used_as_they_are():
    rng = np.random.default_rng(9)
    dt = 1 / 120
    t = np.cumsum(rng.uniform(0.6 * dt, 1.4 * dt, int(25 / dt)))
    t -= t[0]
    r = identify(torsion_trace(viscous=0.01, t=t), torsion_rig())
    assert pytest.approx(J, rel=2e-4) == r.J
    assert r.added_effects == ()


def test_gaps_from_dropped_samples_do_not_inflate_the_noise_floor():
    # 6 % of samples missing in bursts of 1-5 (dropped frames, failed reads)
    trace = torsion_trace(viscous=0.01, t=np.arange(0.0, 20.0, 1 / 100))
    rng = np.random.default_rng(0)
    keep = np.ones(trace.t.size, dtype=bool)
    for start in rng.choice(trace.t.size - 10, 40, replace=False):
        keep[start:start + rng.integers(1, 6)] = False
    r = identify(Trace(trace.t[keep], trace.angle[keep], source="gappy"), torsion_rig())
    assert abs(rms_vs_noise(r) - 1) < 0.2
    assert r.noise_floor == pytest.approx(r.residual_rms, rel=0.2)
    assert "outliers_removed" not in r.flags
    assert pytest.approx(J, rel=2e-4) == r.J
