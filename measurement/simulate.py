"""Physical simulation of a swing: truth for tests, mocks and `moi simulate`.

``Pendulum`` is the truth (rig, J, effects with values); ``simulate_trace``
samples it like a sensor would (rate, jitter, noise, encoder quantisation,
zero offset); ``Swing`` gives θ at any time for live mocks (the simulated
encoder and camera ask for the angle "now"). ``RigidBody`` is a part with a
full inertia tensor: ``RigidBody.mounted`` is the pendulum it makes on a rig
when it swings about any axis of its own frame, its centre of mass off that
axis or not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Mapping, overload

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from .effects import resolve_effects
from .errors import InvalidInput
from .model import Model, omega_n_of
from .rig import Rig
from .trace import Trace

if TYPE_CHECKING:  # the tensor plan only as a type: the simulation reads its axes and offsets
    from .tensor import TensorPlan


@dataclass(frozen=True)
class Pendulum:
    """A pendulum with known truth.

    rig: the rig (its restoring constant turns J into ω_n).
    inertia: J, kg·m² (total about the pivot).
    effects: effect name → {parameter: value}; physical names (c, Tc, mu,
    K, k3, rate) or normalised ones (c_per_J, ...).
    """

    rig: Rig
    inertia: float
    effects: Mapping[str, Mapping[str, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (isinstance(self.inertia, (int, float)) and self.inertia > 0 and math.isfinite(self.inertia)):
            raise InvalidInput(f"inertia must be a finite number > 0 kg·m², got {self.inertia!r}")

    @property
    def omega_n(self) -> float:
        return omega_n_of(self.rig, self.inertia)

    @property
    def model(self) -> Model:
        return Model(self.rig, tuple(resolve_effects(self.effects, self.rig)))

    def parameter_vector(self, theta0: float, omega0: float = 0.0, offset: float = 0.0) -> np.ndarray:
        m = self.model
        values = {e.name: e.normalise(self.effects[e.name], self.inertia) for e in m.effects}
        return m.vector((theta0, omega0, self.omega_n), values, offset)

    def max_step(self, amplitude: float) -> float:
        """Integration step (s) accurate at this amplitude (rad)."""
        return self.model.max_step(self.parameter_vector(amplitude), amplitude)

    def motion(self, t: np.ndarray, theta0: float, omega0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """True θ (rad) and θ' (rad/s) at times t (s), starting at t[0]; sensor effects excluded."""
        x = self.parameter_vector(theta0, omega0)
        return self.model.true_angle(x, np.asarray(t, dtype=float), self.max_step(abs(theta0)))

    def measured(self, t: np.ndarray, theta: np.ndarray, offset: float = 0.0) -> np.ndarray:
        """What the sensor reads (rad) at times t (s, from the first sample) for the true angle θ (rad)."""
        return self.model.measured(self.parameter_vector(0.0, 0.0, offset), np.asarray(t, dtype=float), theta)


@dataclass(frozen=True)
class RigidBody:
    """A rigid part with known truth: its inertia tensor about the centre of mass, in its own frame.

    tensor: the 3×3 inertia matrix T, kg·m² (nᵀ·T·n is the inertia about the unit axis n; its
    off-diagonal entries are −∫xy dm). mass: kg.
    """

    tensor: tuple[tuple[float, float, float], ...]
    mass: float

    def __post_init__(self) -> None:
        T = np.asarray(self.tensor, dtype=float)
        if T.shape != (3, 3) or not np.all(np.isfinite(T)) or not np.allclose(T, T.T):
            raise InvalidInput("a rigid body's tensor must be a finite symmetric 3×3 matrix in kg·m²")
        lam = np.linalg.eigvalsh(T)
        if lam[0] <= 0 or lam[0] + lam[1] < lam[2] * (1 - 1e-12):
            raise InvalidInput(f"no rigid body has the principal moments {lam.tolist()} kg·m² "
                               "(each must be > 0 and the two smaller must sum to at least the largest)")
        if not (isinstance(self.mass, (int, float)) and self.mass > 0 and math.isfinite(self.mass)):
            raise InvalidInput(f"mass must be a finite number > 0 kg, got {self.mass!r}")

    @classmethod
    def from_point_masses(cls, masses: np.ndarray, positions: np.ndarray) -> "RigidBody":
        """The body made of point masses (kg) at positions (N×3, m, any origin)."""
        m = np.asarray(masses, dtype=float)
        r = np.asarray(positions, dtype=float)
        c = r - (m @ r) / m.sum()
        T = np.einsum("i,ij->ij", m, c).T @ c
        T = np.eye(3) * np.trace(T) - T
        return cls(tuple(tuple(row) for row in T.tolist()), float(m.sum()))

    def inertia_about(self, axis: np.ndarray, through: np.ndarray | None = None) -> float:
        """Inertia about the line along ``axis`` (normalised here) through the point ``through`` (m, from
        the centre of mass; None: through it), kg·m²: the tensor moved to that point (Steiner, in tensor
        form T + m·(|p|²·1 − p·pᵀ)) and read along the axis."""
        n = np.asarray(axis, dtype=float)
        n = n / np.linalg.norm(n)
        p = np.zeros(3) if through is None else np.asarray(through, dtype=float)
        T_p = np.asarray(self.tensor, dtype=float) + self.mass * (np.eye(3) * (p @ p) - np.outer(p, p))
        return float(n @ T_p @ n)

    def mounted(self, rig: Rig, axis: np.ndarray, offset: np.ndarray | None = None,
                effects: Mapping[str, Mapping[str, float]] | None = None) -> Pendulum:
        """The pendulum this body makes on ``rig`` swinging about ``axis`` (its own frame), its centre of
        mass at ``offset`` (m) from the swing axis: J = the rig's tare + the body about that axis."""
        through = None if offset is None else -np.asarray(offset, dtype=float)
        J = (rig.tare_inertia or 0.0) + self.inertia_about(axis, through)
        return Pendulum(rig, J, dict(effects or {}))


#: an example part for demonstrations and benchmarks: a bracket whose products of inertia have both signs
#: and whose principal moments are well apart (kg·m², kg)
BRACKET = RigidBody(((0.0120, -0.0015, 0.0008), (-0.0015, 0.0180, 0.0011), (0.0008, 0.0011, 0.0210)), 1.25)


def simulate_set(body: RigidBody, rig: Rig, plan: "TensorPlan", *, releases: int = 1, seed: int = 0,
                 effects: Mapping[str, Mapping[str, float]] | None = None,
                 mounted_axes: Mapping[str, tuple[float, float, float]] | None = None,
                 theta0: float = 0.25, duration: float = 12.0, rate: float = 100.0,
                 noise_std: float = 3e-4) -> list[list[Trace]]:
    """The traces of a whole multi-orientation set: ``body`` mounted on ``rig`` in each orientation of
    ``plan`` (its axis and offset), ``releases`` free swings each. mounted_axes: orientation name →
    the axis the part was really mounted on (a mis-mounting the plan does not know of).
    Effects default to a light viscous damping; theta0 rad, duration s, rate Hz, noise_std rad."""
    effects = {"viscous": {"c": 1.5e-4}} if effects is None else effects
    out = []
    for i, o in enumerate(plan.orientations):
        axis = (mounted_axes or {}).get(o.name, o.axis)
        pendulum = body.mounted(rig, np.asarray(axis), np.asarray(plan.offset_vector(o)), effects)
        out.append([simulate_trace(pendulum, theta0=theta0, duration=duration, rate=rate, noise_std=noise_std,
                                   seed=seed * 1000 + 10 * i + r) for r in range(releases)])
    return out


def quantise(angle: np.ndarray, bits: int) -> np.ndarray:
    """Round to an absolute encoder's resolution of 2π/2^bits rad."""
    if not (isinstance(bits, int) and 4 <= bits <= 32):
        raise InvalidInput(f"encoder resolution must be 4..32 bits, got {bits!r}")
    step = 2.0 * math.pi / (1 << bits)
    return np.round(angle / step) * step


def simulate_trace(
    pendulum: Pendulum,
    *,
    theta0: float,
    duration: float,
    rate: float,
    omega0: float = 0.0,
    offset: float = 0.0,
    noise_std: float = 0.0,
    quantisation_bits: int | None = None,
    jitter: float = 0.0,
    pre_trigger: float = 0.0,
    seed: int | None = None,
) -> Trace:
    """Sample a free swing like a sensor.

    theta0: release angle, rad (held at rest for ``pre_trigger`` s first).
    duration: s after the release; rate: samples per second, Hz.
    noise_std: white angle noise, rad; quantisation_bits: encoder resolution.
    jitter: std of the timestamp jitter as a fraction of the sample interval
    (uneven timestamps, order kept).
    """
    if not (duration > 0 and rate > 0):
        raise InvalidInput(f"duration and rate must be > 0 (got {duration} s, {rate} Hz)")
    if noise_std < 0 or jitter < 0 or pre_trigger < 0:
        raise InvalidInput("noise, jitter and pre-trigger must be >= 0")
    if jitter >= 0.45:
        raise InvalidInput("jitter must be < 0.45 of the sample interval to keep time increasing")
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    n_pre = int(round(pre_trigger * rate))
    n = int(round(duration * rate)) + 1
    t = np.arange(-n_pre, n) * dt
    if jitter:
        t = t + rng.normal(0.0, jitter * dt, t.size).clip(-0.45 * dt, 0.45 * dt)
        t[n_pre] = 0.0
    release = n_pre
    theta = np.empty_like(t)
    theta[:release] = theta0
    theta[release:], _ = pendulum.motion(t[release:], theta0, omega0)
    measured = pendulum.measured(t - t[0], theta, offset)
    if noise_std:
        measured = measured + rng.normal(0.0, noise_std, t.size)
    if quantisation_bits:
        measured = quantise(measured, quantisation_bits)
    t = t - t[0]
    return Trace(t, measured, source="simulation", meta={"truth": {
        "J": pendulum.inertia, "omega_n": pendulum.omega_n, "effects": {k: dict(v) for k, v in pendulum.effects.items()},
        "theta0": theta0, "offset": offset, "noise_std": noise_std, "quantisation_bits": quantisation_bits,
    }})


class Swing:
    """θ(t) of one free swing after a release, for live mocks.

    The swing is integrated once on a fine grid (1 kHz or 40 points per
    period) and read back with cubic Hermite interpolation from θ and θ'.
    """

    def __init__(self, pendulum: Pendulum, theta0: float, duration: float, omega0: float = 0.0):
        steps_per_period = 40.0
        fine = max(1000.0, steps_per_period * pendulum.omega_n / (2 * math.pi))
        t = np.arange(0.0, duration + 2.0 / fine, 1.0 / fine)
        theta, omega = pendulum.motion(t, theta0, omega0)
        self.duration = float(t[-1])
        self.theta0 = float(theta0)
        self._spline = CubicHermiteSpline(t, theta, omega)
        self._final = float(theta[-1])

    @overload
    def angle(self, t_since_release: float) -> float: ...
    @overload
    def angle(self, t_since_release: np.ndarray) -> np.ndarray: ...
    def angle(self, t_since_release: float | np.ndarray) -> float | np.ndarray:
        """True angle (rad) at time(s) after the release (s); θ0 before it.

        A float time gives a float; an array of times, an array of its shape (a 0-d array counts as a float).
        """
        ts = np.asarray(t_since_release, dtype=float)
        out = np.where(ts <= 0, self.theta0, self._spline(np.clip(ts, 0.0, self.duration)))
        out = np.where(ts > self.duration, self._final, out)
        return float(out) if out.ndim == 0 else out
