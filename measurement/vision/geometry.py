"""Pixel to swing angle with the true geometry of a marker on a cylinder.

Top view (the swing axis is vertical)::

        swing axis ●              a marker point at surface angle φ (from the
                   |  \\ R         radius that faces the camera) sits at
                   |   ● marker    R·sin φ laterally and L − R·cos φ deep, i.e.
                   |  /            R·(1 − cos φ) further away than at rest.
                   | /
                   |/ α (bearing of the ray, from the camera–axis line)
        camera     ◉               L: camera optical centre to the swing axis

The bearing of the marker is tan α = R·sin φ / (L − R·cos φ). Solved
exactly for φ (R·sin(φ + α) = L·sin α):

    φ = arcsin((L/R)·sin α) − α

(the monocular-vision torsion pendulum paper, "Research on the Measurement Technology of Rotational Inertia of Rigid Body Based on the Principles of Monocular Vision and Torsion Pendulum",
eq. 11–14, puts R·tan θ for the lateral position: that is not where a point on a cylinder goes;
the error is 0.4 % of the amplitude at 5°.)

The camera's optical axis may be yawed by ψ from the camera–axis line
(ψ > 0 turns it towards +u). A ray seen at the ideal normalised image
coordinate x = X_c/Z_c has the bearing α = ψ + atan(x). The marker's angle
at rest, φ0, need not be zero (a camera placed off the radial line, then
aimed at the marker, is exactly a yawed camera with φ0 ≠ 0); the swing angle
is θ = φ − φ0, and the identification fits that constant as the sensor's
zero offset anyway.
"""

from __future__ import annotations

import math
from typing import overload

import numpy as np

from .config import MarkerGeometry


def axis_distance(marker: MarkerGeometry, rest_angle: float = 0.0) -> float:
    """L, m: camera to swing axis, from D (camera to marker at rest) and the marker's rest angle φ0 (rad).

    From the triangle camera–axis–marker: D² = L² + R² − 2·L·R·cos φ0.
    """
    R, D = marker.radius, marker.distance
    s = math.sin(rest_angle)
    return R * math.cos(rest_angle) + math.sqrt(max(D * D - R * R * s * s, 0.0))


def bearing_from_angle(phi: np.ndarray | float, radius: float, axis_dist: float) -> np.ndarray | float:
    """α, rad: bearing of the marker point at surface angle φ (rad) from the camera–axis line."""
    phi = np.asarray(phi, dtype=float)
    out = np.arctan2(radius * np.sin(phi), axis_dist - radius * np.cos(phi))
    return float(out) if out.ndim == 0 else out


def angle_from_bearing(alpha: np.ndarray | float, radius: float, axis_dist: float) -> np.ndarray | float:
    """φ, rad: surface angle of the marker point seen at bearing α (rad); NaN beyond the cylinder's silhouette."""
    alpha = np.asarray(alpha, dtype=float)
    s = (axis_dist / radius) * np.sin(alpha)
    with np.errstate(invalid="ignore"):
        out = np.where(np.abs(s) <= 1.0, np.arcsin(np.clip(s, -1.0, 1.0)) - alpha, np.nan)
    return float(out) if out.ndim == 0 else out


@overload
def angle_from_normalised(x: float, marker: MarkerGeometry, yaw: float = 0.0, rest_angle: float = 0.0) -> float: ...
@overload
def angle_from_normalised(x: np.ndarray, marker: MarkerGeometry, yaw: float = 0.0,
                          rest_angle: float = 0.0) -> np.ndarray: ...
def angle_from_normalised(x: np.ndarray | float, marker: MarkerGeometry, yaw: float = 0.0,
                          rest_angle: float = 0.0) -> np.ndarray | float:
    """Swing angle θ = φ − φ0 (rad) of the marker seen at ideal normalised image coordinate x.

    A float x gives a float θ; an array of positions, an array of angles of its shape (a 0-d array counts
    as a float).

    yaw: ψ, rad, of the optical axis from the camera–axis line.
    rest_angle: φ0, rad, the marker's surface angle at rest (sets L and the zero).
    """
    L = axis_distance(marker, rest_angle)
    phi = angle_from_bearing(yaw + np.arctan(np.asarray(x, dtype=float)), marker.radius, L)
    return phi - rest_angle


def normalised_from_angle(theta: np.ndarray | float, marker: MarkerGeometry, yaw: float = 0.0,
                          rest_angle: float = 0.0) -> np.ndarray | float:
    """Ideal normalised image coordinate x of the marker at swing angle θ (rad): the forward model."""
    L = axis_distance(marker, rest_angle)
    alpha = bearing_from_angle(np.asarray(theta, dtype=float) + rest_angle, marker.radius, L)
    out = np.tan(np.asarray(alpha) - yaw)
    return float(out) if np.ndim(out) == 0 else out


def d_angle_d_yaw(x: np.ndarray, marker: MarkerGeometry, yaw: float, rest_angle: float = 0.0) -> np.ndarray:
    """∂θ/∂ψ at fixed image coordinate x (dimensionless): the yaw column of the pose fit.

    dφ/dα = (L/R)·cos α / sqrt(1 − ((L/R)·sin α)²) − 1 and ∂α/∂ψ = 1.
    """
    k = axis_distance(marker, rest_angle) / marker.radius
    alpha = yaw + np.arctan(np.asarray(x, dtype=float))
    s = k * np.sin(alpha)
    with np.errstate(invalid="ignore", divide="ignore"):
        return k * np.cos(alpha) / np.sqrt(1.0 - s * s) - 1.0


def visible_limit(marker: MarkerGeometry) -> float:
    """Largest |φ| (rad) at which the marker is still in front of the cylinder's silhouette: cos φ = R/L."""
    return math.acos(marker.radius / marker.axis_distance)
