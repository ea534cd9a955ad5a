"""Pixel ↔ angle: the exact cylinder geometry, against an independent 3-D projection."""

import math

import cv2
import numpy as np
import pytest

from measurement.vision import MarkerGeometry, angle_from_normalised, normalised_from_angle
from measurement.vision.geometry import axis_distance, d_angle_d_yaw, visible_limit

MARKER = MarkerGeometry(radius=0.10, distance=0.25)


def project_with_opencv(theta, yaw=0.0, rest=0.0):
    """The marker point of a cylinder turned by θ, projected by cv2.projectPoints (a separate pinhole model)."""
    R = MARKER.radius
    L = axis_distance(MARKER, rest)
    phi = np.asarray(theta) + rest
    # world: camera at the origin looking along +Z, swing axis vertical at Z = L
    pts = np.stack([R * np.sin(phi), np.zeros_like(phi), L - R * np.cos(phi)], axis=-1).reshape(-1, 1, 3)
    # the camera turned by ψ about the vertical: world → camera is the inverse rotation
    rvec = np.array([0.0, -yaw, 0.0])
    img, _ = cv2.projectPoints(pts, rvec, np.zeros(3), np.eye(3), np.zeros(5))
    return img.reshape(-1, 2)[:, 0]


@pytest.mark.parametrize(("yaw_deg", "rest_deg"), [(0, 0), (4, 0), (-4, 0), (3, 6)])
def test_forward_model_matches_opencv_projection(yaw_deg, rest_deg):
    theta = np.linspace(-1.0, 1.0, 41)
    x = normalised_from_angle(theta, MARKER, math.radians(yaw_deg), math.radians(rest_deg))
    ref = project_with_opencv(theta, math.radians(yaw_deg), math.radians(rest_deg))
    assert np.max(np.abs(x - ref)) < 1e-12


@pytest.mark.parametrize(("yaw_deg", "rest_deg"), [(0, 0), (4, 0), (-2, 5)])
def test_inverse_is_exact(yaw_deg, rest_deg):
    yaw, rest = math.radians(yaw_deg), math.radians(rest_deg)
    theta = np.linspace(-1.1, 1.1, 201)
    back = angle_from_normalised(normalised_from_angle(theta, MARKER, yaw, rest), MARKER, yaw, rest)
    assert np.max(np.abs(back - theta)) < 1e-12


def test_sin_geometry_not_seed_tan_formula():
    """The small-angle R·tan θ lateral position of the monocular-vision torsion pendulum paper reads 0.4 % short at 5° and worse beyond; the exact inverse does not."""
    theta = math.radians(5.0)
    x = normalised_from_angle(theta, MARKER)
    R, U0 = MARKER.radius, MARKER.distance
    # eq. 13 solved for θ by fixed point: R·tan θ = (U0 + (1 − cos θ)·R)·x
    t = 0.0
    for _ in range(100):
        t = math.atan((U0 + (1 - math.cos(t)) * R) * x / R)
    assert (theta - t) / theta == pytest.approx(0.0038, abs=0.0003)
    assert angle_from_normalised(x, MARKER) == pytest.approx(theta, abs=1e-15)


def test_yaw_derivative_matches_finite_difference():
    x = np.linspace(-0.2, 0.2, 9)
    h = 1e-6
    numeric = (angle_from_normalised(x, MARKER, 0.05 + h) - angle_from_normalised(x, MARKER, 0.05 - h)) / (2 * h)
    assert np.allclose(d_angle_d_yaw(x, MARKER, 0.05), numeric, rtol=1e-6)


def test_axis_distance_from_the_triangle():
    rest = math.radians(20)
    L = axis_distance(MARKER, rest)
    D2 = L**2 + MARKER.radius**2 - 2 * L * MARKER.radius * math.cos(rest)
    assert math.sqrt(D2) == pytest.approx(MARKER.distance, rel=1e-12)
    assert axis_distance(MARKER) == pytest.approx(0.35)


def test_beyond_the_silhouette_is_nan_not_an_error():
    limit = visible_limit(MARKER)
    assert math.cos(limit) == pytest.approx(MARKER.radius / MARKER.axis_distance)
    x_edge = normalised_from_angle(limit, MARKER)
    assert math.isnan(angle_from_normalised(1.01 * x_edge, MARKER))
    assert math.isfinite(angle_from_normalised(0.99 * x_edge, MARKER))
