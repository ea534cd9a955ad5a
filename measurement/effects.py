"""The effect library: the parts a pendulum model is composed from.

Equation of motion, normalised by the inertia J (DESIGN.md):

    θ'' = −ω_n²·r(θ) − Σ_effects Σ_j p_j·φ_j(θ, θ', s)

with r(θ) = θ (torsion) or sin θ (compound) and s = ±1 the direction of the
current half-swing. Every dynamic effect is linear in its normalised
parameters p_j (torque / J), which is what makes the equation-error start and
the discovery loop's diagnostics cheap. A sensor effect adds to the measured
angle instead: θ_meas = θ + a + Σ q_j·ψ_j(t).

Adding an effect is adding one small class below: it registers itself by
``name``. The names are a contract (they appear in every output).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Iterable, Sequence

import numpy as np

from .errors import RigError, UnknownEffectError

if TYPE_CHECKING:
    from .rig import Rig

#: name → effect class, filled by ``Effect.__init_subclass__`` in definition order.
EFFECTS: dict[str, type["Effect"]] = {}


@dataclass(frozen=True)
class Parameter:
    """One fitted parameter of an effect.

    name/unit: the fitted, J-normalised quantity (e.g. c_per_J in 1/s).
    physical/physical_unit: the torque-law quantity reported when J is known
    (e.g. c in N·m·s/rad); None when the fitted quantity is already physical.
    lower: lower bound used in fitting (dissipation cannot be negative).
    """

    name: str
    unit: str
    physical: str | None
    physical_unit: str | None
    lower: float = 0.0
    description: str = ""


class Effect:
    """Base class. Subclasses set the class attributes and the few methods."""

    name: ClassVar[str]
    #: "damping" (dissipative torque), "stiffness" (conservative torque) or "sensor".
    role: ClassVar[str]
    parameters: ClassVar[tuple[Parameter, ...]]
    #: rig kinds the effect exists on
    rigs: ClassVar[tuple[str, ...]] = ("torsion", "compound")
    cause: ClassVar[str] = ""
    #: torque law as printed in reports
    law: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "name" in cls.__dict__:
            EFFECTS[cls.name] = cls

    def __init__(self, rig: "Rig"):
        self.rig = rig

    def __repr__(self) -> str:
        return f"<effect {self.name}>"

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    # -- dynamic effects -------------------------------------------------------
    def basis(self, theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """Regressors φ_j, shape (n, m): this effect's θ'' contribution is −φ·p (rad/s²)."""
        raise NotImplementedError

    #: This effect's θ'' term Σ p_j φ_j as one Python expression in x (θ, rad),
    #: v (θ', rad/s), s (±1, direction of the half-swing) and p0, p1, ... (its
    #: parameters), using cos/sin/abs. The integrator is generated from these
    #: strings so that its inner loop makes no function calls; a test checks
    #: each term against ``basis``.
    term: ClassVar[str] = ""
    #: Static friction capacity at rest (rad/s², a θ'' magnitude) as an
    #: expression in x and p0...; empty when the effect cannot hold the pendulum.
    holding_term: ClassVar[str] = ""

    def equivalent_viscous(self, values: Sequence[float], amplitude: float, omega: float) -> float:
        """c_eq/J (1/s) dissipating the same energy per cycle at this amplitude (rad) and ω (rad/s)."""
        return 0.0

    # -- sensor effects --------------------------------------------------------
    def sensor_basis(self, t: np.ndarray) -> np.ndarray:
        """Regressors ψ_j(t), shape (n, m), added to the measured angle (rad)."""
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

    def physical(self, values: Sequence[float], inertia: float | None, omega_n: float) -> dict[str, float | None]:
        """Torque-law values from the normalised ones; None where J is unknown."""
        out: dict[str, float | None] = {}
        for p, v in zip(self.parameters, values):
            if p.physical is not None:
                out[p.physical] = None if inertia is None else v * inertia
        return out


class Viscous(Effect):
    name = "viscous"
    role = "damping"
    parameters = (Parameter("c_per_J", "1/s", "c", "N·m·s/rad", description="viscous coefficient over J"),)
    cause = "linear damping: eddy currents, material damping"
    law = "c·θ'"

    def basis(self, theta, omega):
        return omega[:, None]

    term = "p0 * v"

    def equivalent_viscous(self, values, amplitude, omega):
        return float(values[0])

    decrement_order = 1
    decrement_words = "grows in proportion to the amplitude"
    envelope = "exponential"


class Coulomb(Effect):
    name = "coulomb"
    role = "damping"
    parameters = (
        Parameter("Tc_per_J", "rad/s²", "Tc", "N·m", description="friction torque over J (compound: μ·m·g/J)"),
    )
    cause = "dry (bearing) friction"
    law = "T_c·sgn θ' (torsion); μ·m·g·cos θ·sgn θ' (compound)"

    def basis(self, theta, omega):
        s = np.sign(omega)  # the half-swing's direction
        if self.rig.kind == "compound":
            return (s * np.cos(theta))[:, None]
        return s[:, None]

    @property
    def term(self) -> str:  # type: ignore[override]
        return "p0 * s * cos(x)" if self.rig.kind == "compound" else "p0 * s"

    @property
    def holding_term(self) -> str:  # type: ignore[override]
        return "p0 * abs(cos(x))" if self.rig.kind == "compound" else "p0"

    def equivalent_viscous(self, values, amplitude, omega):
        # energy per cycle 4·T_c·A equals π·c_eq·ω·A²
        return 4.0 * float(values[0]) / (math.pi * amplitude * omega) if amplitude > 0 and omega > 0 else 0.0

    extra_units = {"mu": "m", "mu_over_S": "1"}

    decrement_order = 0
    decrement_words = "has a constant part, {value:.3g} rad per swing, which only dry friction gives"
    envelope = "linear"

    def evidence(self, diag):
        base = super().evidence(diag)
        why = [base] if base else []
        if diag.stopped:
            why.append("the pendulum stopped dead within the record, which only dry friction does")
        return "; ".join(why)

    def physical(self, values, inertia, omega_n):
        b = float(values[0])
        if self.rig.kind == "compound":
            out: dict[str, float | None] = {"mu": None}
            if inertia is not None and self.rig.mass is not None:
                out["mu"] = b * inertia / (self.rig.mass * self.rig.g)
            # μ/S = b/ω_n² is identifiable even when m and S are unknown.
            out["mu_over_S"] = b / omega_n**2
            return out
        return {"Tc": None if inertia is None else b * inertia}


class Quadratic(Effect):
    name = "quadratic"
    role = "damping"
    parameters = (Parameter("K_per_J", "1/rad", "K", "N·m·s²/rad²", description="air-drag coefficient over J"),)
    cause = "air drag"
    law = "K·θ'·|θ'|"

    def basis(self, theta, omega):
        return (omega * np.abs(omega))[:, None]

    # s·θ'² rather than θ'·|θ'|: identical within a half-swing and smooth for
    # the integrator's intermediate stages near a turning point.
    term = "p0 * s * v * v"

    def equivalent_viscous(self, values, amplitude, omega):
        return 8.0 * float(values[0]) * amplitude * omega / (3.0 * math.pi)

    decrement_order = 2
    decrement_words = "grows with the square of the amplitude"
    envelope = "hyperbolic"


class CubicStiffness(Effect):
    name = "cubic_stiffness"
    role = "stiffness"
    parameters = (
        Parameter(
            "k3_per_J", "1/(rad²·s²)", "k3", "N·m/rad³", lower=-np.inf,
            description="cubic spring coefficient over J (>0 hardening)",
        ),
    )
    rigs = ("torsion",)
    cause = "nonlinear (hardening or softening) spring"
    law = "k₃·θ³"

    def basis(self, theta, omega):
        return (theta**3)[:, None]

    term = "p0 * x * x * x"

    def evidence(self, diag):
        if abs(diag.freq_amp_t) >= 4:
            kind = "rises" if diag.freq_amp_slope > 0 else "falls"
            return f"the swing frequency {kind} with amplitude beyond the model (t = {diag.freq_amp_t:.1f}), as a nonlinear spring makes it"
        return ""


class Drift(Effect):
    name = "drift"
    role = "sensor"
    parameters = (
        Parameter("rate", "rad/s", None, None, lower=-np.inf, description="sensor zero drift rate b"),
    )
    cause = "encoder/camera zero drift"
    law = "θ_meas = θ + a + b·t"

    def sensor_basis(self, t):
        return (t - t[0])[:, None]

    def evidence(self, diag):
        why = []
        if abs(diag.centre_t) >= 4:
            why.append(f"the swing centre moves at {diag.centre_slope:+.2g} rad/s (t = {diag.centre_t:.1f})")
        if diag.low_frequency_fraction >= 0.3:
            why.append(f"{100 * diag.low_frequency_fraction:.0f} % of the residual power is slower than the swing")
        return "; ".join(why)

    def physical(self, values, inertia, omega_n):
        return {}


def resolve_effects(names: Iterable[str], rig: "Rig") -> list[Effect]:
    """Instantiate effects by name for this rig, in library order.

    Raises UnknownEffectError for a name outside the library and RigError for
    an effect that does not exist on this kind of rig.
    """
    names = list(names)
    seen: set[str] = set()
    for n in names:
        if n not in EFFECTS:
            hint = " (the zero offset is always fitted; it is not an effect)" if n in ("offset", "zero_offset") else ""
            raise UnknownEffectError(f"unknown effect {n!r}{hint}; expected one of {', '.join(EFFECTS)}")
        if n in seen:
            raise UnknownEffectError(f"effect {n!r} listed twice")
        seen.add(n)
        if rig.kind not in EFFECTS[n].rigs:
            raise RigError(f"effect {n!r} does not exist on a {rig.kind} rig (only on: {', '.join(EFFECTS[n].rigs)})")
    return [EFFECTS[n](rig) for n in EFFECTS if n in seen]


def candidate_effects(rig: "Rig", present: Iterable[str]) -> list[Effect]:
    """Library effects that apply to this rig and are not already in the model."""
    present = set(present)
    return [cls(rig) for n, cls in EFFECTS.items() if n not in present and rig.kind in cls.rigs]
