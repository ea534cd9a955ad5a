"""The effect library: the parts a pendulum model is composed from.

Equation of motion, normalised by the inertia J:

    θ'' = −ω_n²·r(θ) − Σ_effects Σ_j p_j·φ_j(θ, θ', s)

with r(θ) = θ (torsion), sin θ (compound) or a wire suspension's law (``measurement.restoring``) and s = ±1 the direction of the
current half-swing. Every dynamic effect is linear in its normalised
parameters p_j (torque / J), which is what makes the equation-error start and
the discovery loop's diagnostics cheap. A sensor effect adds to the measured
angle instead: θ_meas = θ + a + Σ q_j·ψ_j(t, θ).

Adding an effect is adding one small class below (and a line in the README's
effect table): it registers itself by ``name`` and carries everything that is
particular to it: its law (one expression, ``term``, from which both the
integrator and the vectorised regressors are made), its bounds, its start
value, how its physical values are given and reported, where it is
identifiable, and its evidence in the residual. The names are a contract
(they appear in every output).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Iterable, Mapping, Protocol, Sequence

import numpy as np

from .errors import InvalidInput, RigError, UnknownEffectError


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

#: name → effect class, filled by ``Effect.__init_subclass__`` in definition order.
EFFECTS: dict[str, type["Effect"]] = {}


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

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "name" in cls.__dict__:
            EFFECTS[cls.name] = cls

    @classmethod
    def offered_on(cls, kind: str) -> bool:
        """Whether the discovery loop offers this effect as a candidate on a ``kind`` rig."""
        return kind in (cls.offered or cls.rigs)

    @classmethod
    def unweighed_law(cls, kind: str) -> str | None:
        """The restoring law this effect mimics (``mimics``) where a ``kind`` rig may hold it but the loop
        does not offer it, so that discovery never weighs the two; None otherwise."""
        law = cls.mimics
        if law is None or kind not in EFFECTS[law].rigs or EFFECTS[law].offered_on(kind):
            return None
        return law

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


class Viscous(Effect):
    name = "viscous"
    role = "damping"
    parameters = (Parameter("c_per_J", "1/s", "c", "N·m·s/rad", description="viscous coefficient over J"),)
    cause = "linear damping: eddy currents, material damping"
    law = "c·θ'"

    term = "p0 * v"

    def equivalent_viscous(self, values, amplitude, omega):
        return float(values[0])

    def fallback_start(self, peak_times, peak_amplitudes):
        # logarithmic decrement of the envelope: A ∝ exp(−c/(2J)·t)
        if peak_amplitudes.size < 3:
            return None
        slope = np.polyfit(peak_times, np.log(peak_amplitudes), 1)[0]
        return [max(0.0, -2.0 * float(slope))]

    decrement_order = 1
    decrement_words = "grows in proportion to the amplitude"
    envelope = "exponential"


class Coulomb(Effect):
    name = "coulomb"
    role = "damping"
    parameters: ClassVar[tuple[Parameter, ...]] = (  # any length: Dahl friction adds its pre-sliding angle
        Parameter("Tc_per_J", "rad/s²", "Tc", "N·m", description="friction torque over J (compound: μ·m·g/J)"),
    )
    cause = "dry (bearing) friction"
    law = "T_c·sgn θ' (torsion); μ·m·g·cos θ·sgn θ' (compound)"

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

    @classmethod
    def given_names(cls, kind):
        # on a compound rig the friction may be given as μ (m): T = μ·m·g·cos θ
        return super().given_names(kind) + ("mu",) if kind == "compound" else super().given_names(kind)

    @classmethod
    def default_given(cls, kind):
        return "mu" if kind == "compound" else super().default_given(kind)

    def normalise(self, given, inertia):
        if self.rig.kind == "compound" and "mu" in given and not {"Tc", "Tc_per_J"} & set(given):
            if set(given) != {"mu"}:
                raise InvalidInput(f"coulomb: unknown parameter(s) {sorted(set(given) - {'mu'})}")
            if inertia is None or self.rig.mass is None:
                raise InvalidInput("coulomb: mu (m) needs the rig's mass and the inertia; give Tc_per_J instead")
            return [float(given["mu"]) * self.rig.mass * self.rig.g / inertia]
        return super().normalise(given, inertia)

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


class Dahl(Coulomb):
    name = "dahl"
    role = "damping"
    parameters = (
        Parameter("Tc_per_J", "rad/s²", "Tc", "N·m", description="sliding friction torque over J (compound: μ·m·g/J)"),
        Parameter("theta_c", "rad", None, None, upper=0.5,
                  description="pre-sliding angle: the friction reaches 63 % of T_c this far from a turning point"
                              " (beyond 0.5 rad it would be a spring, not friction)"),
    )
    cause = "pre-sliding (micro-slip) stiffness of a dry bearing, or a cable: a spring at small amplitude, "\
            "dry friction at large"
    law = "dT/dθ = (T_c/θ_c)·(1 − T/T_c·sgn θ') (Dahl; compound: T_c ∝ cos θ)"
    refines = "coulomb"
    # the pre-sliding spring makes small swings faster, as a restoring law softer at large angles does
    mimics = "cubic_stiffness"

    # The Dahl law integrates in closed form over a half-swing: with z = T/T_c
    # and z_r its value at the last turning point x_r,
    #     z = s − s·(1 − s·z_r)·exp(−|x − x_r|/θ_c),
    # so the friction is a function of the angle travelled since the reversal
    # and the integrator needs no third state. θ_c = 0 is Coulomb friction.
    _z = "(s - s * (1.0 - s * zr) * exp(-abs(x - xr) / p1) if p1 > 0.0 else s)"
    memory = _z
    memory_sharp = "p0 != 0.0 and p1 > 0.0"

    @property
    def term(self) -> str:  # type: ignore[override]
        return f"p0 * {self._z} * cos(x)" if self.rig.kind == "compound" else f"p0 * {self._z}"

    @property
    def holding_term(self) -> str:  # type: ignore[override]
        # A pre-sliding spring does not stick: it keeps oscillating, less and less. At θ_c = 0
        # it is Coulomb friction, which must stick as Coulomb's does: without that, the
        # friction would flip at every reversal near rest, ever faster (a Zeno chatter). Below
        # a micro-radian the spring is stiffer than any record resolves and its oscillation
        # near rest would take millions of reversals: it holds as dry friction does.
        return f"({super().holding_term} if p1 <= {self.stiff_below!r} else 0.0)"

    #: pre-sliding angle (rad) below which the friction holds the pendulum at rest as Coulomb's does
    stiff_below: ClassVar[float] = 1e-6

    @property
    def memory_force(self) -> str:  # type: ignore[override]
        return "p0 * zr * cos(x)" if self.rig.kind == "compound" else "p0 * zr"

    def basis(self, theta, omega):
        # Linear in T_c only: its regressor is the sliding (Coulomb) one; θ_c
        # enters through refined_start and parameter_scales, not a regression.
        theta = np.asarray(theta, dtype=float)
        col = np.sign(np.asarray(omega, dtype=float)) * (np.cos(theta) if self.rig.kind == "compound" else 1.0)
        return np.stack([np.broadcast_to(col, theta.shape), np.zeros_like(theta)], axis=1)

    def refined_start(self, refined_values, amplitudes):
        smallest = max(float(amplitudes[1]), 1e-6)
        # the pre-sliding angle shows where the swings come down to it
        return [[float(refined_values[0]), f * smallest] for f in (0.1, 0.3, 1.0)]

    def parameter_scales(self, amplitude):
        return [None, 0.1 * max(amplitude, 1e-6)]

    def frequency_factor(self, values, omega_n, amplitude):
        # below θ_c the friction is a spring T_c/θ_c: the swing is faster there
        tc, thc = float(values[0]), float(values[1])
        if thc <= 0.0:
            return 1.0
        return min(math.sqrt(1.0 + max(tc, 0.0) / (thc * max(omega_n, 1e-9) ** 2)), 10.0)

    def equivalent_viscous(self, values, amplitude, omega):
        # sliding over all but ≈θ_c of each half-swing
        thc = float(values[1])
        return super().equivalent_viscous(values, amplitude, omega) * max(0.0, 1.0 - thc / amplitude) if amplitude > 0 else 0.0

    extra_units = {**Coulomb.extra_units, "presliding_stiffness": "N·m/rad", "presliding_stiffness_per_J": "1/s²"}

    def evidence(self, diag):
        if diag.freq_amp_t <= -4:
            return (f"the swing frequency rises as the swing decays, beyond the model (t = {diag.freq_amp_t:.1f}):"
                    f" a stiffness that acts only at small amplitude, as a bearing's pre-sliding spring")
        return ""

    def normalise(self, given, inertia):
        if "theta_c" not in given:
            raise InvalidInput("dahl: missing value theta_c (rad), the pre-sliding angle")
        # the sliding friction is given as for dry friction
        rest = {k: v for k, v in given.items() if k != "theta_c"}
        return Coulomb(self.rig).normalise(rest, inertia) + [float(given["theta_c"])]

    def physical(self, values, inertia, omega_n):
        out = super().physical(values, inertia, omega_n)
        tc, thc = float(values[0]), float(values[1])
        k = tc / thc if thc > 0 else None  # θ_c = 0: dry friction, no spring to report
        out["presliding_stiffness_per_J"] = k
        out["presliding_stiffness"] = None if inertia is None or k is None else k * inertia
        return out


class Quadratic(Effect):
    name = "quadratic"
    role = "damping"
    parameters = (Parameter("K_per_J", "1/rad", "K", "N·m·s²/rad²", description="air-drag coefficient over J"),)
    cause = "air drag"
    law = "K·θ'·|θ'|"

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
    # On a compound rig m·g·S·sin θ is the law of a rigid body on a pivot: a cubic term there is a
    # suspension's own law (a bifilar's), which a user declares; offered, it would stand in for
    # pre-sliding friction and the sensor's scale, whose signatures it shares
    offered = ("torsion",)
    cause = "nonlinear (hardening or softening) spring; on a compound rig, a suspension's law beyond sin θ"
    law = "k₃·θ³"

    term = "p0 * x * x * x"

    def amplitude_stiffness(self, values, amplitude):
        # k₃θ³ over a swing θ = A cos ωt: its fundamental is (3/4)·k₃·A²·θ
        return 0.75 * float(values[0]) * amplitude**2

    def frequency_factor(self, values, omega_n, amplitude):
        # a hardening spring raises the frequency at large amplitude
        return math.sqrt(1.0 + 3.0 * max(float(values[0]), 0.0) / max(omega_n, 1e-9) ** 2 * amplitude**2)

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

    def sensor_basis(self, t, theta):
        return (t - t[0])[:, None]

    def evidence(self, diag):
        why = []
        if abs(diag.centre_t) >= 4:
            unit = "rad/s²" if self.rig.measures == "rate" else "rad/s"
            why.append(f"the swing centre moves at {diag.centre_slope:+.2g} {unit} (t = {diag.centre_t:.1f})")
        if diag.low_frequency_fraction >= 0.3:
            why.append(f"{100 * diag.low_frequency_fraction:.0f} % of the residual power is slower than the swing")
        return "; ".join(why)

    def physical(self, values, inertia, omega_n):
        return {}


class Gain(Effect):
    name = "gain"
    role = "sensor"
    parameters = (
        Parameter("g_minus_1", "1", None, None, lower=-0.9, description="sensor scale error g − 1"),
    )
    #: a scale error is told apart from the amplitude only through the sin θ of a compound rig
    rigs = ("compound",)
    cause = "camera/encoder scale error (distance, focal length, marker geometry)"
    scale_parameters = ("g_minus_1",)
    law = "θ_meas = a + g·θ"
    extra_units = {"g": "1"}
    #: below this amplitude sin θ is too close to θ for g to be told from the amplitude
    min_amplitude = 0.5
    # a scale error changes how the frequency depends on the amplitude, as another restoring law does
    mimics = "cubic_stiffness"

    def sensor_basis(self, t, theta):
        return np.asarray(theta, dtype=float)[:, None]

    @classmethod
    def given_names(cls, kind):
        return ("g_minus_1", "g")

    @classmethod
    def default_given(cls, kind):
        return "g"

    def normalise(self, given, inertia):
        if set(given) == {"g"}:
            return [float(given["g"]) - 1.0]
        return super().normalise(given, inertia)

    def evidence(self, diag):
        if abs(diag.freq_amp_t) >= 4:
            return (f"the swing frequency depends on the amplitude differently from sin θ at the measured scale"
                    f" (t = {diag.freq_amp_t:.1f}): the angle's scale is off")
        return ""

    def physical(self, values, inertia, omega_n):
        return {"g": 1.0 + float(values[0])}


class View(Effect):
    name = "view"
    role = "sensor"
    parameters = (
        Parameter("stretch", "1", None, None, lower=-0.5, upper=0.5,
                  description="image stretched along the horizontal against the vertical (e₁)"),
        Parameter("shear", "1", None, None, lower=-0.5, upper=0.5,
                  description="image stretched along a diagonal (e₂): makes the two half-swings unequal"),
    )
    #: told apart from the swing only at large angles, where sin 2θ and cos 2θ are not θ and θ²
    rigs = ("compound",)
    #: a camera's geometry: a gyro has no view
    readings = ("angle",)
    scale_parameters = ("stretch",)
    cause = "camera not square to the swing plane (oblique view, lens): the image of the swing is an ellipse"
    law = "θ_meas = a + θ + e₁·sin 2θ + e₂·(cos 2θ − 1) (an affine image of the marker's direction, to first order)"
    min_amplitude = 0.5
    # its stretch changes the angle's scale with the angle, and so how the frequency depends on the amplitude
    mimics = "cubic_stiffness"

    def sensor_basis(self, t, theta):
        # the direction (sin θ, cos θ) seen through the image map [[1+e₁, e₂], [e₂, 1−e₁]]:
        # ∂θ_meas/∂e₁ = sin 2θ, ∂θ_meas/∂e₂ = cos 2θ (minus 1: the offset is fitted apart)
        theta = np.asarray(theta, dtype=float)
        return np.stack([np.sin(2 * theta), np.cos(2 * theta) - 1.0], axis=1)

    def evidence(self, diag):
        if abs(diag.asymmetry_t) >= 4:
            return (f"the two half-swings differ in amplitude by {diag.asymmetry:+.2g} rad (t = {diag.asymmetry_t:.1f}),"
                    f" as an oblique view of the swing makes them")
        return ""

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
        other = getattr(EFFECTS.get(n), "refines", None)
        if other is not None and other in names:
            raise UnknownEffectError(f"effects {n!r} and {other!r} exclude each other: {n} contains {other} as a limit")
    for n in names:
        if n not in EFFECTS:
            hint = " (the zero offset is always fitted; it is not an effect)" if n in ("offset", "zero_offset") else ""
            raise UnknownEffectError(f"unknown effect {n!r}{hint}; expected one of {', '.join(EFFECTS)}")
        if n in seen:
            raise UnknownEffectError(f"effect {n!r} listed twice")
        seen.add(n)
        if rig.kind not in EFFECTS[n].rigs:
            raise RigError(f"effect {n!r} does not exist on a {rig.kind} rig (only on: {', '.join(EFFECTS[n].rigs)})")
        if rig.measures not in EFFECTS[n].readings:
            raise RigError(f"effect {n!r} does not exist in a sensor that reads {rig.measures} "
                           f"(only in one that reads: {', '.join(EFFECTS[n].readings)})")
    return [EFFECTS[n](rig) for n in EFFECTS if n in seen]


def candidate_effects(rig: "Rig", present: Iterable[str]) -> list[Effect]:
    """Library effects that apply to this rig and are not already in the model.

    A rig whose sensor is calibrated is offered no effect that fits the angle's scale.
    """
    present = set(present)
    contained = {EFFECTS[n].refines for n in present if n in EFFECTS}
    return [cls(rig) for n, cls in EFFECTS.items()
            if n not in present and n not in contained and cls.offered_on(rig.kind) and rig.measures in cls.readings
            and (cls.refines is None or cls.refines in present)
            and not (rig.sensor_calibrated and cls.scale_parameters)]


def with_effect(present: Iterable[str], effect: Effect) -> tuple[str, ...]:
    """The effect names of a model after adding ``effect`` (which replaces the effect it refines)."""
    return tuple(n for n in present if n != effect.refines) + (effect.name,)
