"""A pendulum model composed from effects, and its parameter vector.

Parameter vector (all SI, J-normalised where dynamic):

    theta0, omega0      initial state at the first fitted sample (rad, rad/s)
    omega_n             small-amplitude natural angular frequency (rad/s)
    <dynamic effects>   e.g. c_per_J, Tc_per_J, K_per_J, k3_per_J
    offset              sensor zero offset a (rad), always fitted
    <sensor effects>    e.g. rate (drift, rad/s)

A sensor reads the angle or, a gyro, the angular rate (``Rig.measures``): the
model's reading is then the simulated velocity θ', and offset and sensor
terms act on the rate (offset in rad/s, drift in rad/s²).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Iterable, Mapping, Sequence

import numpy as np

from .effect_base import Effect
from .effects import resolve_effects
from .errors import InvalidInput
from .integrator import Dynamics
from .rig import Rig

STATE_PARAMS = ("theta0", "omega0", "omega_n")

#: a parameter vector: the float array the fitter iterates on, or a sequence of floats
Vector = Sequence[float] | np.ndarray


@dataclass(frozen=True)
class Model:
    """The equation of motion and sensor model made of ``effects`` on ``rig``.

    Its parameter vector has a named layout (``layout``: name → slice):
    theta0, omega0, omega_n, each dynamic effect, offset, each sensor effect.
    Read a vector by name with ``value(x, "omega_n")`` or ``values(x, "coulomb")``.
    """

    rig: Rig
    effects: tuple[Effect, ...]

    @classmethod
    def from_names(cls, rig: Rig, names: Iterable[str]) -> "Model":
        return cls(rig, tuple(resolve_effects(names, rig)))

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    @cached_property
    def dynamic(self) -> tuple[Effect, ...]:
        return tuple(e for e in self.effects if e.role != "sensor")

    @cached_property
    def sensor(self) -> tuple[Effect, ...]:
        return tuple(e for e in self.effects if e.role == "sensor")

    @cached_property
    def layout(self) -> dict[str, slice]:
        """Name → slice of the parameter vector: the state, each effect (by its name) and the offset."""
        out: dict[str, slice] = {}
        i = 0
        for name in STATE_PARAMS:
            out[name] = slice(i, i + 1)
            i += 1
        for e in self.dynamic:
            out[e.name] = slice(i, i + len(e.parameters))
            i += len(e.parameters)
        out["offset"] = slice(i, i + 1)
        i += 1
        for e in self.sensor:
            out[e.name] = slice(i, i + len(e.parameters))
            i += len(e.parameters)
        return out

    @property
    def size(self) -> int:
        return max(s.stop for s in self.layout.values())

    def index(self, name: str) -> int:
        """Position of a scalar parameter: a state name, "offset" or "effect.parameter"."""
        if name in STATE_PARAMS or name == "offset":
            return self.layout[name].start
        return self.names.index(name)

    def value(self, x: Vector, name: str) -> float:
        return float(x[self.index(name)])

    def values(self, x: Vector, effect: str) -> list[float]:
        """An effect's parameter values, in its ``parameters`` order."""
        return [float(v) for v in np.asarray(x)[self.layout[effect]]]

    @cached_property
    def names(self) -> tuple[str, ...]:
        """Names of the parameter vector, in order ("effect.parameter" for an effect's)."""
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
        return self.layout["offset"].start

    def _per_parameter(self, state: Sequence, offset, of_effect) -> list:
        out = list(state)
        for e in self.dynamic:
            out += [of_effect(p) for p in e.parameters]
        out.append(offset)
        for e in self.sensor:
            out += [of_effect(p) for p in e.parameters]
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = self._per_parameter([-np.inf, -np.inf, 0.0], -np.inf, lambda p: p.lower)
        hi = self._per_parameter([np.inf, np.inf, np.inf], np.inf, lambda p: p.upper)
        return np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)

    def split(self, x: Vector) -> dict[str, list[float]]:
        """Effect name → its parameter values, from a parameter vector."""
        return {e.name: self.values(x, e.name) for e in self.effects}

    def vector(self, state: Sequence[float], effect_values: Mapping[str, Sequence[float]], offset: float = 0.0) -> np.ndarray:
        """A parameter vector from (theta0, omega0, omega_n), effect name → values, and the offset."""
        x = np.zeros(self.size)
        x[: len(STATE_PARAMS)] = state
        x[self.layout["offset"]] = offset
        for e in self.effects:
            x[self.layout[e.name]] = effect_values.get(e.name, [0.0] * len(e.parameters))
        return x

    def frequency_factor(self, x: Vector, amplitude: float) -> float:
        """Highest swing frequency over ω_n at this amplitude (rad), from every effect's own knowledge."""
        w = self.value(x, "omega_n")
        f = 1.0
        for e in self.dynamic:
            f *= e.frequency_factor(self.values(x, e.name), w, amplitude)
        return f

    def max_step(self, x: Vector, amplitude: float) -> float:
        """Integration step (s) that keeps ω·h ≤ 0.05 at this amplitude (rad)."""
        return 0.05 / (max(self.value(x, "omega_n"), 1e-9) * self.frequency_factor(x, amplitude))

    def dynamics(self, x: Vector) -> Dynamics:
        return Dynamics(self.rig.kind, self.dynamic, [self.values(x, e.name) for e in self.dynamic], self.rig.geometry)

    @property
    def measures(self) -> str:
        """What the sensor reads: "angle" (rad) or "rate" (rad/s)."""
        return self.rig.measures

    def reading(self, theta: np.ndarray, omega: np.ndarray | None) -> np.ndarray:
        """What the pendulum gives the sensor: its angle θ (rad), or its rate θ' (rad/s) on a rate sensor."""
        if self.rig.measures == "angle":
            return theta
        if omega is None:
            raise ValueError("a rate sensor reads the velocity: pass omega (rad/s)")
        return omega

    def sensor_columns(self, t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Columns of the measured-reading model that are linear: offset, then sensor effects.

        theta: the pendulum's ``reading`` (its angle, or its rate on a rate sensor)."""
        cols = [np.ones_like(t)[:, None]] + [e.sensor_basis(t, theta) for e in self.sensor]
        return np.hstack(cols)

    def true_angle(self, x: Vector, t: np.ndarray, max_step: float) -> tuple[np.ndarray, np.ndarray]:
        """θ, θ' of the pendulum itself (no sensor terms) at times t."""
        return self.dynamics(x).integrate(t, self.value(x, "theta0"), self.value(x, "omega0"),
                                          self.value(x, "omega_n"), max_step)

    def measured(self, x: Vector, t: np.ndarray, theta: np.ndarray, omega: np.ndarray | None = None) -> np.ndarray:
        """The sensor's reading from the true swing θ (rad), θ' (rad/s) at times t: θ + a + sensor terms
        (rad) on an angle sensor, θ' + a + sensor terms (rad/s) on a rate sensor (which needs omega)."""
        r = self.reading(theta, omega)
        if not self.sensor:  # the offset alone: the same sum without building a column of ones
            return r + float(x[self.n_dynamic])
        lin = np.asarray(x[self.n_dynamic:], dtype=float)
        return r + self.sensor_columns(t, r) @ lin

    def amplitude(self, x: Vector, y: np.ndarray) -> float:
        """The swing's largest angle (rad) as the readings y show it about the offset in x."""
        a = float(np.max(np.abs(y - self.value(x, "offset"))))
        if self.rig.measures == "rate":
            a /= max(self.value(x, "omega_n"), 1e-9)
        return max(abs(self.value(x, "theta0")), a)


def omega_n_of(rig: Rig, inertia: float) -> float:
    """ω_n = sqrt(C/J), rad/s, for a rig whose restoring constant is known."""
    c = rig.restoring_constant
    if c is None:
        needs = {"torsion": "stiffness", "compound": "mass and com_distance"}.get(rig.kind, "mass")
        raise InvalidInput(f"{rig.kind} rig lacks {needs}: cannot turn J into ω_n")
    if not inertia > 0:
        raise InvalidInput(f"inertia must be > 0 kg·m², got {inertia!r}")
    return math.sqrt(c / inertia)
