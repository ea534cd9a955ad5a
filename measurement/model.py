"""A pendulum model composed from effects, and its parameter vector.

Parameter vector (all SI, J-normalised where dynamic):

    theta0, omega0      initial state at the first fitted sample (rad, rad/s)
    omega_n             small-amplitude natural angular frequency (rad/s)
    <dynamic effects>   e.g. c_per_J, Tc_per_J, K_per_J, k3_per_J
    offset              sensor zero offset a (rad), always fitted
    <sensor effects>    e.g. rate (drift, rad/s)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

import numpy as np

from .effects import Effect, resolve_effects
from .errors import InvalidInput
from .integrator import Dynamics
from .rig import Rig

STATE_PARAMS = ("theta0", "omega0", "omega_n")
STATE_UNITS = {"theta0": "rad", "omega0": "rad/s", "omega_n": "rad/s", "offset": "rad"}


@dataclass(frozen=True)
class Model:
    """The equation of motion and sensor model made of ``effects`` on ``rig``."""

    rig: Rig
    effects: tuple[Effect, ...]

    @classmethod
    def from_names(cls, rig: Rig, names: Iterable[str]) -> "Model":
        return cls(rig, tuple(resolve_effects(names, rig)))

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    @property
    def dynamic(self) -> tuple[Effect, ...]:
        return tuple(e for e in self.effects if e.role != "sensor")

    @property
    def sensor(self) -> tuple[Effect, ...]:
        return tuple(e for e in self.effects if e.role == "sensor")

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the parameter vector, in order."""
        out = list(STATE_PARAMS)
        for e in self.dynamic:
            out += [f"{e.name}.{p.name}" for p in e.parameters]
        out.append("offset")
        for e in self.sensor:
            out += [f"{e.name}.{p.name}" for p in e.parameters]
        return tuple(out)

    @property
    def n_dynamic(self) -> int:
        """Parameters that need a simulation to differentiate (state + dynamic effects)."""
        return len(STATE_PARAMS) + sum(len(e.parameters) for e in self.dynamic)

    def units(self) -> tuple[str, ...]:
        out = [STATE_UNITS[n] for n in STATE_PARAMS]
        for e in self.dynamic:
            out += [p.unit for p in e.parameters]
        out.append("rad")
        for e in self.sensor:
            out += [p.unit for p in e.parameters]
        return tuple(out)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [-np.inf, -np.inf, 0.0]
        for e in self.dynamic:
            lo += [p.lower for p in e.parameters]
        lo.append(-np.inf)
        for e in self.sensor:
            lo += [p.lower for p in e.parameters]
        return np.asarray(lo, dtype=float), np.full(len(lo), np.inf)

    def split(self, x: Sequence[float]) -> dict[str, list[float]]:
        """Effect name → its parameter values, from a parameter vector."""
        out: dict[str, list[float]] = {}
        i = len(STATE_PARAMS)
        for e in self.dynamic:
            out[e.name] = [float(v) for v in x[i:i + len(e.parameters)]]
            i += len(e.parameters)
        i += 1  # offset
        for e in self.sensor:
            out[e.name] = [float(v) for v in x[i:i + len(e.parameters)]]
            i += len(e.parameters)
        return out

    def dynamics(self, x: Sequence[float]) -> Dynamics:
        values = self.split(x)
        return Dynamics(self.rig.kind, self.dynamic, [values[e.name] for e in self.dynamic])

    def sensor_columns(self, t: np.ndarray) -> np.ndarray:
        """Columns of the measured-angle model that are linear: offset, then sensor effects."""
        cols = [np.ones_like(t)[:, None]] + [e.sensor_basis(t) for e in self.sensor]
        return np.hstack(cols)

    def true_angle(self, x: Sequence[float], t: np.ndarray, max_step: float) -> tuple[np.ndarray, np.ndarray]:
        """θ, θ' of the pendulum itself (no sensor terms) at times t."""
        return self.dynamics(x).integrate(t, x[0], x[1], x[2], max_step)

    def predict(self, x: Sequence[float], t: np.ndarray, max_step: float) -> np.ndarray:
        """Measured angle θ + a + sensor terms at times t, rad."""
        theta, _ = self.true_angle(x, t, max_step)
        lin = np.asarray(x[self.n_dynamic:], dtype=float)
        return theta + self.sensor_columns(t) @ lin


def normalise_effect_values(rig: Rig, effect: Effect, given: Mapping[str, float], inertia: float | None) -> list[float]:
    """Fitted (J-normalised) values of an effect from physical or normalised ones.

    given: parameter name → value; either the physical name (c, Tc, mu, K,
    k3; needs ``inertia`` in kg·m²) or the normalised one (c_per_J, ...).
    """
    values = []
    for p in effect.parameters:
        if p.name in given:
            values.append(float(given[p.name]))
            continue
        if effect.name == "coulomb" and rig.kind == "compound" and "mu" in given:
            if inertia is None or rig.mass is None:
                raise InvalidInput("coulomb: mu (m) needs the rig's mass and the inertia; give Tc_per_J instead")
            values.append(float(given["mu"]) * rig.mass * rig.g / inertia)
            continue
        if p.physical is not None and p.physical in given:
            if inertia is None:
                raise InvalidInput(f"{effect.name}: {p.physical} needs the inertia J; give {p.name} instead")
            values.append(float(given[p.physical]) / inertia)
            continue
        accepted = [p.name] + ([p.physical] if p.physical else []) + (["mu"] if effect.name == "coulomb" and rig.kind == "compound" else [])
        raise InvalidInput(f"{effect.name}: missing value; expected one of {', '.join(accepted)}")
    accepted_names = {p.name for p in effect.parameters} | {p.physical for p in effect.parameters if p.physical}
    if effect.name == "coulomb" and rig.kind == "compound":
        accepted_names.add("mu")
    extra = set(given) - accepted_names
    if extra:
        raise InvalidInput(f"{effect.name}: unknown parameter(s) {sorted(extra)}")
    return values


def omega_n_of(rig: Rig, inertia: float) -> float:
    """ω_n = sqrt(C/J), rad/s, for a rig whose restoring constant is known."""
    c = rig.restoring_constant
    if c is None:
        raise InvalidInput(f"{rig.kind} rig lacks {'stiffness' if rig.kind == 'torsion' else 'mass and com_distance'}: cannot turn J into ω_n")
    if not inertia > 0:
        raise InvalidInput(f"inertia must be > 0 kg·m², got {inertia!r}")
    return math.sqrt(c / inertia)
