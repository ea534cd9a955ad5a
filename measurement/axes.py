"""The swing's axis in a sensor's frame: a three-axis gyro taped to a swinging body at any angle.

A rigid body swinging about a fixed axis n turns at θ'·n: in the sensor's frame every rate vector lies
along one direction, whatever the sensor's mounting. That direction is the rates' first principal
component, and the rate about it is their projection on it (the swing's whole rate, where one sensor
axis reads it times the cosine between them). Pure computation on arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class SwingAxis:
    """direction: unit vector in the sensor's frame (one component per column, the largest positive);
    share: fraction of the rates' variance about their median along it; nearest: index of the sensor
    axis closest to it; cosine: the direction's component on that axis (1: the swing is about it);
    rate: the rates projected on the direction, in their unit."""

    direction: tuple[float, ...]
    share: float
    nearest: int
    cosine: float
    rate: np.ndarray

    def cosine_with(self, i: int) -> float:
        """|cos| of the angle between the swing's axis and sensor axis ``i`` (its share of the swing's rate)."""
        return abs(self.direction[i])


def swing_axis(rates: np.ndarray, use: np.ndarray | None = None) -> SwingAxis:
    """The swing's axis from rates (n samples × k axes); use: the samples that swing (default: all)."""
    r = np.asarray(rates, dtype=float)
    sel = r if use is None else r[use]
    x = sel - np.median(sel, axis=0)
    values, vectors = np.linalg.eigh(x.T @ x)
    v = vectors[:, int(np.argmax(values))]
    nearest = int(np.argmax(np.abs(v)))
    v = v if v[nearest] > 0 else -v
    total = float(np.sum(values))
    share = float(np.max(values) / total) if total > 0 else 0.0
    return SwingAxis(tuple(float(c) for c in v), share, nearest, float(abs(v[nearest])), r @ v)
