"""Two markers on the pendulum: the camera's oblique view measured from their constant distance, and removed."""

import numpy as np
import pytest

from measurement import identify
from measurement.effects import candidate_effects
from measurement.errors import RigError, VisionError
from measurement.reports import result_report
from measurement.rig import Rig
from measurement.simulate import Pendulum, simulate_trace
from measurement.vision.marker_pair import MarkerTrack, measure_view, pair_angle, pair_trace, parse_marker_csv

RIG = Rig(kind="compound", mass=1.0, com_distance=1.0, g=9.81, declared=("viscous",))
CALIBRATED = Rig(kind="compound", mass=1.0, com_distance=1.0, g=9.81, declared=("viscous",), sensor_calibrated=True)
OMEGA_N = 5.8
J = 9.81 / OMEGA_N**2


def _rotation(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def _image(theta, stretch, shear, roll=0.1, rng=None, pixel_noise=0.3):
    """Markers 0.3 m and 0.42 m below the pivot, seen through an affine view at 800 px/m, rounded to whole px."""
    u = np.column_stack([np.sin(theta), np.cos(theta)])
    view = 800.0 * _rotation(roll) @ (np.eye(2) + np.array([[stretch, shear], [shear, -stretch]]))
    pivot = np.array([640.0, 200.0])
    a = pivot + (0.30 * u) @ view.T
    b = pivot + (0.42 * u) @ view.T
    if rng is not None:
        a = np.round(a + rng.normal(0, pixel_noise, a.shape))
        b = np.round(b + rng.normal(0, pixel_noise, b.shape))
    return a, b


def _in_image_axes(stretch, shear, roll=0.1):
    """The symmetric distortion R·E·Rᵀ that the image axes see (the roll itself only offsets the angle)."""
    e = _rotation(roll) @ np.array([[stretch, shear], [shear, -stretch]]) @ _rotation(roll).T
    return e[0, 0], e[0, 1]


def _swing(seed, theta0=1.5, duration=20.0):
    return simulate_trace(Pendulum(RIG, J, {"viscous": {"c_per_J": 0.05}}), theta0=theta0, duration=duration,
                          rate=60, noise_std=0.0, seed=seed)


@pytest.mark.parametrize(("stretch", "shear"), [(0.03, -0.02), (-0.05, 0.0), (0.0, 0.0)])
def test_view_is_measured_from_the_markers_distance(stretch, shear):
    theta = _swing(1).angle
    a, b = _image(theta, stretch, shear, rng=np.random.default_rng(5))
    view = measure_view(a, b)
    want_stretch, want_shear = _in_image_axes(stretch, shear)
    assert abs(view.stretch - want_stretch) < max(4 * view.stretch_std, 2e-3)
    assert abs(view.shear - want_shear) < max(4 * view.shear_std, 2e-3)
    assert 0 < view.stretch_std < 0.01 and 0 < view.shear_std < 0.01
    expected_ratio = (1 - np.hypot(want_stretch, want_shear)) / (1 + np.hypot(want_stretch, want_shear))
    assert abs(view.axis_ratio - expected_ratio) < max(4 * view.axis_ratio_std, 3e-3)
    # corrected, the angle is the pendulum's up to a constant (the camera's roll) and the pixel noise;
    # as seen, it carries the view's law stretch·sin 2θ + shear·cos 2θ
    basis = np.column_stack([np.ones_like(theta), np.sin(2 * theta), np.cos(2 * theta)])
    left = np.linalg.lstsq(basis, view.angle(a, b) - theta, rcond=None)[0]
    seen = np.linalg.lstsq(basis, pair_angle(a, b) - theta, rcond=None)[0]
    assert np.all(np.abs(left[1:]) < 2e-3)
    if stretch or shear:
        assert np.hypot(*seen[1:]) > 0.5 * np.hypot(stretch, shear)


def test_a_wrong_blob_is_rejected_and_counted_not_measured():
    theta = _swing(2).angle
    a, b = _image(theta, 0.03, 0.01, rng=np.random.default_rng(7))
    wild = np.arange(40, len(theta), 97)
    b = b.copy()
    b[wild] += [60.0, -35.0]
    view = measure_view(a, b)
    want_stretch, want_shear = _in_image_axes(0.03, 0.01)
    assert view.rejected >= len(wild)
    assert view.samples + view.rejected == len(theta)
    assert abs(view.stretch - want_stretch) < 3e-3 and abs(view.shear - want_shear) < 3e-3


def test_the_corrected_trace_gives_the_true_omega_n_with_the_sensor_declared_calibrated():
    trace = _swing(3, theta0=2.0, duration=25.0)
    a, b = _image(trace.angle, 0.04, 0.015, rng=np.random.default_rng(3))
    track = MarkerTrack(trace.t, a, b, source="synthetic")
    seen = identify(pair_trace(track, None), CALIBRATED)
    corrected = identify(pair_trace(track, measure_view(a, b)), CALIBRATED)
    # the view seen through a calibrated sensor biases ω_n; measured and removed, it does not
    assert abs(seen.omega_n - OMEGA_N) > 5 * seen.omega_n_std
    assert abs(corrected.omega_n - OMEGA_N) < 4 * corrected.omega_n_std
    assert not {"gain", "view"} & set(corrected.effects) and not {"gain", "view"} & set(seen.effects)
    assert corrected.sensor_calibrated and "sensor_scale_fitted" not in corrected.flags
    assert corrected.acquisition["view"]["samples"] == len(trace)


def test_a_calibrated_sensor_is_offered_no_effect_that_fits_its_scale():
    offered = {e.name for e in candidate_effects(CALIBRATED, ("viscous",))}
    assert offered and not {"gain", "view"} & offered
    assert {"gain", "view"} <= {e.name for e in candidate_effects(RIG, ("viscous",))}
    with pytest.raises(RigError, match="calibrated"):
        Rig(kind="compound", declared=("viscous", "gain"), sensor_calibrated=True)
    assert Rig.from_dict({"rig": {"kind": "compound"}, "sensor": {"calibrated": True}}).sensor_calibrated
    assert Rig.from_dict(CALIBRATED.to_dict()) == CALIBRATED
    with pytest.raises(RigError, match="true or false"):
        Rig.from_dict({"rig": {"kind": "compound"}, "sensor": {"calibrated": "yes"}})


def test_view_refuses_what_cannot_measure_it():
    theta = _swing(4).angle
    a, b = _image(theta, 0.02, 0.0)
    with pytest.raises(VisionError, match="at least 20"):
        measure_view(a[:10], b[:10])
    with pytest.raises(VisionError, match="turns by only"):
        measure_view(*_image(np.full(100, 0.3) + 0.01 * np.sin(np.arange(100)), 0.02, 0.0))
    with pytest.raises(VisionError, match="n×2"):
        measure_view(np.zeros((50, 3)), np.ones((50, 3)))
    with pytest.raises(VisionError, match="distinct"):
        measure_view(a, a)


def test_marker_csv_parsing_drops_and_counts_lost_markers():
    text = ["# provenance", "t,ax,ay,bx,by,extra", "0,1,2,3,4,x", "0.1,,,3,4,", "0.2,1,2,3.5,4.5,y"]
    track = parse_marker_csv(text, source="m.csv")
    assert track.missing == 1
    assert track.t.tolist() == [0.0, 0.2]
    assert track.b.tolist() == [[3.0, 4.0], [3.5, 4.5]]
    with pytest.raises(VisionError, match="missing column.*by"):
        parse_marker_csv(["t,ax,ay,bx", "0,1,2,3"])
    with pytest.raises(VisionError, match="line 2: non-numeric"):
        parse_marker_csv(["t,ax,ay,bx,by", "0,1,2,3,four"])
    with pytest.raises(VisionError, match="no time"):
        parse_marker_csv(["t,ax,ay,bx,by", ",1,2,3,4"])
    with pytest.raises(VisionError, match="no row with both markers"):
        parse_marker_csv(["t,ax,ay,bx,by", "0,,,3,4"])


def test_a_view_in_perspective_is_said_to_be_more_than_oblique():
    theta = _swing(6, theta0=2.0).angle
    a, b = _image(theta, 0.03, 0.01, rng=np.random.default_rng(11))
    oblique = measure_view(a, b)
    assert oblique.distance_pattern < 0.005 and "nothing else shows" in oblique.report()
    # the same swing with its left side 15 % nearer the camera than its right (a swing plane turned in depth)
    u = np.column_stack([np.sin(theta), np.cos(theta)])
    depth = lambda r: 1.0 + 0.15 * r * u[:, 0] / 0.42  # noqa: E731 - scale at each marker's position
    pivot = np.array([640.0, 200.0])
    a_p = pivot + 800.0 * 0.30 * u * depth(0.30)[:, None]
    b_p = pivot + 800.0 * 0.42 * u * depth(0.42)[:, None]
    perspective = measure_view(a_p, b_p)
    assert perspective.distance_pattern > 0.03
    assert "more than an oblique view explains" in perspective.report()


def test_the_views_uncertainty_is_carried_into_omega_n():
    import dataclasses

    trace = _swing(8, theta0=2.0, duration=25.0)
    a, b = _image(trace.angle, 0.04, 0.015, rng=np.random.default_rng(8))
    track = MarkerTrack(trace.t, a, b, source="synthetic")
    view = measure_view(a, b)
    r = identify(pair_trace(track, view), CALIBRATED)
    assert r.omega_n_std_calibration is not None and r.omega_n_std_calibration > 0
    assert "the camera view's calibration adds" in result_report(r)
    assert r.to_dict()["omega_n_std_calibration"] == r.omega_n_std_calibration
    # against refits with the view moved by its 1σ (stretch, then shear)
    s = np.array(view.matrix).reshape(2, 2)
    moved = []
    for d_stretch, d_shear in ((view.stretch_std, 0.0), (0.0, view.shear_std)):
        e = np.array([[d_stretch, d_shear], [d_shear, -d_stretch]])
        shifted = dataclasses.replace(view, matrix=tuple(((np.eye(2) - e) @ s).ravel()))
        moved.append(identify(pair_trace(track, shifted), CALIBRATED).omega_n - r.omega_n)
    refit = float(np.hypot(moved[0], moved[1]))
    assert 0.7 < r.omega_n_std_calibration / refit < 1.4
    # a trace read as it is carries none
    assert identify(pair_trace(track, None), CALIBRATED).omega_n_std_calibration is None


def test_a_record_whose_view_was_measured_is_not_given_a_fitted_scale_again():
    trace = _swing(9, theta0=2.0, duration=25.0)
    a, b = _image(trace.angle, 0.04, 0.015, rng=np.random.default_rng(9))
    track = MarkerTrack(trace.t, a, b, source="synthetic")
    r = identify(pair_trace(track, measure_view(a, b)), RIG)  # the rig says nothing of its sensor
    assert r.sensor_calibrated and not {"gain", "view"} & {name for s in r.steps for name in s.candidates}
    assert r.omega_n_std_calibration is not None
    assert abs(r.omega_n - OMEGA_N) < 4 * np.hypot(r.omega_n_std, r.omega_n_std_calibration)


def test_a_rig_that_would_fit_the_measured_view_again_is_refused():
    trace = _swing(10, theta0=2.0, duration=20.0)
    a, b = _image(trace.angle, 0.04, 0.015, rng=np.random.default_rng(10))
    measured = pair_trace(MarkerTrack(trace.t, a, b, source="track.csv"), measure_view(a, b))
    with pytest.raises(RigError, match="track.csv: the camera's view was measured.*declares view"):
        identify(measured, Rig(kind="compound", declared=("viscous", "view")))
