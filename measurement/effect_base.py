"""What every effect of the library (``measurement.effects``) is: the ``Effect`` base class with its
``Parameter``s, and the ``Rig`` it reads. An effect declares its law, bounds, start, units and evidence as
class attributes and a few methods; the library lists the effects there are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Mapping, Protocol, Sequence

import numpy as np

from .errors import InvalidInput


class Rig(Protocol):
    """What an effect reads of its rig (``measurement.rig.Rig``, whose module imports this one)."""

    @property
    def kind(self) -> str: ...
    @property
    def mass(self) -> float | None: ...
    @property
    def g(self) -> float: ...
    @property
    def sensor_calibrated(self) -> bool: ...
    @property
    def measures(self) -> str: ...

#: names the effects' ``term`` expressions may use, in their numpy form
_NUMPY_NAMES = {"cos": np.cos, "sin": np.sin, "abs": np.abs, "exp": np.exp}

@dataclass(frozen=True)
class Parameter:
    """One fitted parameter of an effect.

    name/unit: the fitted, J-normalised quantity (e.g. c_per_J in 1/s).
    physical/physical_unit: the torque-law quantity reported when J is known
    (e.g. c in N·m·s/rad); None when the fitted quantity is already physical.
    lower: lower bound used in fitting (dissipation cannot be negative).
    upper: upper bound (where the law stops meaning what its name says).
    """

    name: str
    unit: str
    physical: str | None
    physical_unit: str | None
    lower: float = 0.0
    description: str = ""
    #: upper bound used in fitting
    upper: float = math.inf


class Effect:
    """Base class. Subclasses set the class attributes and the few methods."""

    name: ClassVar[str]
    #: "damping" (dissipative torque), "stiffness" (conservative torque) or "sensor".
    role: ClassVar[str]
    parameters: ClassVar[tuple[Parameter, ...]]
    #: rig kinds the effect exists on (may be declared, is integrated)
    rigs: ClassVar[tuple[str, ...]] = ("torsion", "compound", "bifilar", "trifilar")
    #: rig kinds the discovery loop offers it on as a candidate (None: all of ``rigs``)
    offered: ClassVar[tuple[str, ...] | None] = None
    #: what a sensor must read for the effect to exist in it ("angle", "rate"; ``Rig.measures``)
    readings: ClassVar[tuple[str, ...]] = ("angle", "rate")
    cause: ClassVar[str] = ""
    #: torque law as printed in reports
    law: ClassVar[str] = ""

    @classmethod
    def offered_on(cls, kind: str) -> bool:
        """Whether the discovery loop offers this effect as a candidate on a ``kind`` rig."""
        return kind in (cls.offered or cls.rigs)

    def __init__(self, rig: "Rig"):
        self.rig = rig

    def __repr__(self) -> str:
        return f"<effect {self.name}>"

    # -- dynamic effects -------------------------------------------------------
    #: This effect's θ'' term Σ p_j φ_j (the law) as one Python expression in x
    #: (θ, rad), v (θ', rad/s), s (±1, direction of the half-swing) and p0, p1,
    #: ... (its parameters), using cos/sin/abs. It is the one form of the law:
    #: the integrator is generated from it (no function call in its inner
    #: loop) and ``basis`` evaluates it on arrays.
    term: ClassVar[str] = ""

    def basis(self, theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """Regressors φ_j, shape (n, m): this effect's θ'' contribution is −φ·p (rad/s²).

        The term is linear in its parameters, so column j is the term with
        p_j = 1 and the others 0, evaluated on the arrays.
        """
        theta = np.asarray(theta, dtype=float)
        omega = np.asarray(omega, dtype=float)
        env = dict(_NUMPY_NAMES, x=theta, v=omega, s=np.sign(omega))
        code = compile(self.term, f"<{self.name}.term>", "eval")
        cols = []
        for j in range(len(self.parameters)):
            env.update({f"p{i}": float(i == j) for i in range(len(self.parameters))})
            cols.append(np.broadcast_to(eval(code, env), theta.shape))  # library terms only
        return np.stack(cols, axis=1)
    #: Static friction capacity at rest (rad/s², a θ'' magnitude) as an
    #: expression in x and p0...; empty when the effect cannot hold the pendulum.
    holding_term: ClassVar[str] = ""
    #: An effect that remembers the last turning point (``term`` then also
    #: uses xr, where it was, rad, and zr, a state it had there): ``memory`` is
    #: the new zr at a reversal at x reached in direction s, ``memory_force``
    #: its θ'' contribution at rest there (in x, zr, p0...). One effect at most.
    memory: ClassVar[str] = ""
    memory_force: ClassVar[str] = ""
    #: condition (in p0...) under which the remembered force turns over within a
    #: small fraction of a step after a reversal
    memory_sharp: ClassVar[str] = "False"
    #: sensor parameters that change the angle's scale (nominal 0): ω_n is read through them
    scale_parameters: ClassVar[tuple[str, ...]] = ()
    #: The effect this one generalises (it contains it as a limit and replaces
    #: it in a model): offered as a candidate only where that one is present.
    refines: ClassVar[str | None] = None
    #: The restoring-law effect whose signature this one shares (what it does to the swing a
    #: restoring law can also do): on a rig where that law is not offered, the data cannot weigh
    #: the two by their discovery, and the law's reading of ω_n is a rival (``identification.rivals.law_rival``).
    mimics: ClassVar[str | None] = None

    def refined_start(self, refined_values: Sequence[float], amplitudes: Sequence[float]) -> list[list[float]]:
        """Start values that reproduce (nearly) the refined effect with ``refined_values``.

        amplitudes: (largest, smallest) swing amplitude of the record, rad.
        Several starts may be given; the fit keeps the best.
        """
        raise NotImplementedError

    def parameter_scales(self, amplitude: float) -> list[float | None]:
        """Typical size of each parameter at this amplitude (rad); None: from the regressors."""
        return [None] * len(self.parameters)

    def equivalent_viscous(self, values: Sequence[float], amplitude: float, omega: float) -> float:
        """c_eq/J (1/s) dissipating the same energy per cycle at this amplitude (rad) and ω (rad/s)."""
        return 0.0

    def frequency_factor(self, values: Sequence[float], omega_n: float, amplitude: float) -> float:
        """Highest swing frequency over ω_n at this amplitude (rad) (sets the integration step)."""
        return 1.0

    def amplitude_stiffness(self, values: Sequence[float], amplitude: float) -> float:
        """What this law adds to ω² (1/s²) for a swing of this amplitude (rad), to first order (the
        describing function: the linear spring that stores the same work over the swing); 0 for a law
        whose frequency does not depend on the amplitude."""
        return 0.0

    def fallback_start(self, peak_times: np.ndarray, peak_amplitudes: np.ndarray) -> list[float] | None:
        """Start values when the equation-error regression is unusable (None: zeros).

        peak_times (s) and |peak| amplitudes (rad) of the well-measured swings.
        """
        return None

    #: below this amplitude (rad) the effect cannot be told apart from the swing
    min_amplitude: ClassVar[float] = 0.0

    def identifiable(self, amplitude: float) -> bool:
        """Whether a record of this amplitude (rad) can tell the effect apart (else never a candidate)."""
        return amplitude >= self.min_amplitude

    # -- sensor effects --------------------------------------------------------
    def sensor_basis(self, t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Regressors ψ_j(t, θ), shape (n, m), added to the sensor's reading.

        t: time since the first fitted sample (s); theta: what the pendulum gives the sensor:
        its true angle (rad), or its angular rate (rad/s) on a rate sensor (a gyro), whose
        zero, drift and scale then act on the rate.
        """
        raise NotImplementedError

    # -- reporting -------------------------------------------------------------
    #: units of physical outputs that are not a parameter's physical name
    extra_units: ClassVar[dict[str, str]] = {}

    def unit_of(self, physical_name: str) -> str:
        for p in self.parameters:
            if p.physical == physical_name:
                return p.physical_unit or ""
        return self.extra_units.get(physical_name, "")

    #: damping effects: the term of the per-swing amplitude loss ΔA = d0 + d1·A + d2·A²
    #: that is this effect's signature, how to say it, and the envelope law it produces
    decrement_order: ClassVar[int | None] = None
    decrement_words: ClassVar[str] = ""
    envelope: ClassVar[str] = ""

    def evidence(self, diag) -> str:
        """Why the residual diagnostics (``Diagnostics``) point to this effect; "" if they do not."""
        why = []
        k = self.decrement_order
        if k is not None and diag.decrement_t[k] >= 3:
            words = self.decrement_words.format(value=diag.decrement[k])
            why.append(f"the amplitude lost per swing {words} (t = {diag.decrement_t[k]:.1f})")
        if self.envelope and diag.envelope_law and diag.envelope_law.startswith(self.envelope):
            why.append(f"the measured envelope decays {self.envelope}ly")
        return "; ".join(why)

    @classmethod
    def given_names(cls, kind: str) -> tuple[str, ...]:
        """Names a user may give this effect's values by on a ``kind`` rig (normalised, then physical)."""
        out: list[str] = []
        for p in cls.parameters:
            out.append(p.name)
            out += [p.physical] if p.physical else []
        return tuple(out)

    @classmethod
    def default_given(cls, kind: str) -> str:
        """The name a value given without one (``viscous=2e-4``) is taken for: the first physical one."""
        first = cls.parameters[0]
        return first.physical or first.name

    def normalise(self, given: Mapping[str, float], inertia: float | None) -> list[float]:
        """Fitted (J-normalised) values from physical or normalised ones.

        given: parameter name → value, by any of ``given_names``; physical
        names need ``inertia`` (kg·m²).
        """
        values = []
        for p in self.parameters:
            if p.name in given:
                values.append(float(given[p.name]))
            elif p.physical is not None and p.physical in given:
                if inertia is None:
                    raise InvalidInput(f"{self.name}: {p.physical} needs the inertia J; give {p.name} instead")
                values.append(float(given[p.physical]) / inertia)
            else:
                raise InvalidInput(f"{self.name}: missing value; expected one of {', '.join(self.given_names(self.rig.kind))}")
        extra = set(given) - set(self.given_names(self.rig.kind))
        if extra:
            raise InvalidInput(f"{self.name}: unknown parameter(s) {sorted(extra)}")
        return values

    def physical(self, values: Sequence[float], inertia: float | None, omega_n: float) -> dict[str, float | None]:
        """Torque-law values from the normalised ones; None where J is unknown."""
        out: dict[str, float | None] = {}
        for p, v in zip(self.parameters, values):
            if p.physical is not None:
                out[p.physical] = None if inertia is None else v * inertia
        return out
