"""The effect library: the parts a pendulum model is composed from.

Equation of motion, normalised by the inertia J:

    θ'' = −ω_n²·r(θ) − Σ_effects Σ_j p_j·φ_j(θ, θ', s)

with r(θ) = θ (torsion), sin θ (compound) or a wire suspension's law (``measurement.restoring``) and s = ±1 the direction of the
current half-swing. Every dynamic effect is linear in its normalised
parameters p_j (torque / J), which is what makes the equation-error start and
the discovery loop's diagnostics cheap. A sensor effect adds to the measured
angle instead: θ_meas = θ + a + Σ q_j·ψ_j(t, θ).

Adding an effect is adding one small class below, a line in ``EFFECTS`` (and a line in the README's
effect table): it is listed by ``name`` and carries everything that is
particular to it: its law (one expression, ``term``, from which both the
integrator and the vectorised regressors are made), its bounds, its start
value, how its physical values are given and reported, where it is
identifiable, and its evidence in the residual. The names are a contract
(they appear in every output).
"""

from __future__ import annotations

import math
from typing import ClassVar, Iterable

import numpy as np

from .effect_base import Effect, Parameter, Rig
from .errors import InvalidInput, RigError, UnknownEffectError


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


#: name → effect class, the library's effects in order (the names are a contract: they appear in every output)
EFFECTS: dict[str, type[Effect]] = {e.name: e for e in (Viscous, Coulomb, Dahl, Quadratic, CubicStiffness, Drift,
                                                         Gain, View)}


def unweighed_law(effect: type[Effect], kind: str) -> str | None:
    """The restoring law ``effect`` mimics (``Effect.mimics``) where a ``kind`` rig may hold it but the loop
    does not offer it, so that discovery never weighs the two; None otherwise."""
    law = effect.mimics
    if law is None or kind not in EFFECTS[law].rigs or EFFECTS[law].offered_on(kind):
        return None
    return law


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
