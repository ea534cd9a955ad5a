"""Camera yaw from the swing itself: the projection fit, on exact image coordinates of simulated swings."""

import math

import numpy as np
import pytest

from measurement import Pendulum, Trace, identify
from measurement.vision import estimate_yaw, normalised_from_angle
from measurement.vision.geometry import angle_from_normalised

from .conftest import CAMERA, J_TRUE, MARKER, RIG

T = np.arange(0.0, 20.0, 1 / 60)
PIXEL_NOISE = 0.02  # px, about what the tracker leaves at σ = 2 grey levels


def observed(effects, theta0, yaw_deg, rest_deg=0.0, seed=1):
    theta, _ = Pendulum(RIG, J_TRUE, effects).motion(T, theta0)
    x = normalised_from_angle(theta, MARKER, math.radians(yaw_deg), math.radians(rest_deg))
    return theta, x + np.random.default_rng(seed).normal(0.0, PIXEL_NOISE / CAMERA.fx, T.size)


@pytest.mark.parametrize("effects", [{"viscous": {"c": 1.5e-4}}, {"coulomb": {"Tc": 2e-3}},
                                     {"viscous": {"c": 1e-4}, "quadratic": {"K": 2e-3}}])
@pytest.mark.parametrize("yaw_deg", [-4.0, 0.0, 4.0])
def test_yaw_recovered_whatever_the_damping(effects, yaw_deg):
    _, x = observed(effects, 0.2, yaw_deg)
    pose = estimate_yaw(T, x, MARKER)
    assert pose.estimated
    assert pose.yaw_deg == pytest.approx(yaw_deg, abs=0.05)
    assert 0 < pose.yaw_std_deg < 0.05


def test_camera_moved_sideways_and_reaimed():
    """Marker not facing the camera at rest (φ0 = 5°): yaw and rest angle both come out."""
    _, x = observed({"viscous": {"c": 1.5e-4}}, 0.2, 3.0, rest_deg=5.0)
    pose = estimate_yaw(T, x, MARKER)
    assert pose.yaw_deg == pytest.approx(3.0, abs=0.05)
    assert math.degrees(pose.rest_angle) == pytest.approx(5.0, abs=0.05)


def test_small_swing_still_within_a_degree():
    _, x = observed({"viscous": {"c": 1.5e-4}}, math.radians(4.0), 4.0)
    pose = estimate_yaw(T, x, MARKER)
    assert pose.yaw_deg == pytest.approx(4.0, abs=1.0)
    assert pose.yaw_std_deg < 0.5


def test_glitches_do_not_pull_the_yaw():
    _, x = observed({"viscous": {"c": 1.5e-4}}, 0.2, 4.0)
    x = x.copy()
    x[[100, 400, 700]] += 30 / CAMERA.fx  # three frames 30 px off (a mistracked edge)
    assert estimate_yaw(T, x, MARKER).yaw_deg == pytest.approx(4.0, abs=0.05)


def test_too_short_to_tell():
    _, x = observed({"viscous": {"c": 1.5e-4}}, 0.2, 4.0)
    short = T < 2.0
    pose = estimate_yaw(T[short], x[short], MARKER)
    assert not pose.estimated and "half-swings" in pose.reason
    still = estimate_yaw(T, np.full(T.size, 0.01), MARKER)
    assert not still.estimated


def test_uncorrected_yaw_leaves_structure_the_correction_removes():
    """Why correct: 4° of yaw ignored leaves a residual 30× the noise and an unmodeled_residual flag."""
    theta, x = observed({"viscous": {"c": 1.5e-4}}, 0.2, 4.0)
    naive = identify(Trace(T, angle_from_normalised(x, MARKER)), RIG)
    pose = estimate_yaw(T, x, MARKER)
    fixed = identify(Trace(T, angle_from_normalised(x, MARKER, pose.yaw, pose.rest_angle)), RIG)
    assert "unmodeled_residual" in naive.flags and "unmodeled_residual" not in fixed.flags
    assert naive.residual_rms > 10 * fixed.residual_rms
    assert pytest.approx(J_TRUE, rel=1e-4) == fixed.J
    assert fixed.damping["viscous"]["c"].value == pytest.approx(1.5e-4, rel=0.01)


def _peak_bytes(minutes: float) -> int:
    """Peak memory (numpy's allocations, as tracemalloc counts them) of the yaw estimate of a swing this long."""
    import tracemalloc

    t = np.arange(0.0, 60.0 * minutes, 1 / 60)
    theta, _ = Pendulum(RIG, J_TRUE, {"viscous": {"c": 2e-5}}).motion(t, 0.2)  # swings to the end of the record
    x = normalised_from_angle(theta, MARKER, math.radians(3.0)) + np.random.default_rng(3).normal(
        0.0, PIXEL_NOISE / CAMERA.fx, t.size)
    tracemalloc.start()
    try:
        pose = estimate_yaw(t, x, MARKER)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert pose.estimated and pose.yaw_deg == pytest.approx(3.0, abs=0.05)
    return peak


def test_memory_grows_with_the_samples_not_samples_times_knots():
    """A record four times as long holds four times the samples and four times the knots: a dense design
    matrix would take sixteen times the memory (at 8 minutes, 29,000 × 1,400 × 8 bytes: 320 MB, twice)."""
    short, long = _peak_bytes(2.0), _peak_bytes(8.0)
    assert long < 6 * short, (short, long)
    assert long < 60e6, long  # about 1 kB a sample


def test_a_gap_longer_than_a_knot_span_still_gives_the_yaw():
    """Ten seconds without a sample (the marker lost): the yaw of the dense QR fit the design matrix gave."""
    t = np.arange(0.0, 60.0, 1 / 60)
    theta, _ = Pendulum(RIG, J_TRUE, {"viscous": {"c": 1.5e-4}}).motion(t, 0.2)
    x = normalised_from_angle(theta, MARKER, math.radians(3.0)) + np.random.default_rng(1).normal(
        0.0, PIXEL_NOISE / CAMERA.fx, t.size)
    seen = (t < 10.0) | (t > 20.0)
    pose = estimate_yaw(t[seen], x[seen], MARKER)
    assert pose.estimated and pose.yaw_deg == pytest.approx(2.977812, abs=1e-6)  # the dense QR's, to 1e-11 σ


def test_a_column_no_sample_reaches_is_pinned_and_the_others_fitted():
    from scipy import sparse

    from measurement.vision.pose import _LeastSquares

    rng = np.random.default_rng(2)
    dense = rng.normal(size=(50, 4))
    dense[:, 2] = 0.0  # a B-spline whose knot span the samples never reach
    y = rng.normal(size=50)
    fit = _LeastSquares(sparse.csr_array(dense))
    kept = np.delete(dense, 2, axis=1)
    expected = np.linalg.lstsq(kept, y, rcond=None)[0]
    np.testing.assert_allclose(np.delete(fit.coefficients(y), 2), expected, rtol=1e-10)
    np.testing.assert_allclose(fit.residual(y), y - kept @ expected, atol=1e-12)
