"""The uncertainty budget of a measured inertia, in the sense of the GUM.

JCGM 100:2008 ("Evaluation of measurement data — Guide to the expression of
uncertainty in measurement", the GUM) propagates the standard uncertainties
u(x_i) of the inputs x_i of a measurement model y = f(x_1, …, x_N) to the
combined standard uncertainty of y through the sensitivity coefficients
c_i = ∂f/∂x_i (GUM 5.1.2, 5.2.2):

    u_c²(y) = Σ (c_i·u(x_i))² + 2·Σ_{i<j} c_i·c_j·r(x_i, x_j)·u(x_i)·u(x_j)

The correlation terms matter here: a torsion rig's stiffness k and tare
inertia I0 come out of one regression (``moi calibrate``) and are strongly
correlated, so J_object = k/ω_n² − I0 is not "J's σ ⊕ I0's σ".

The expanded uncertainty U = k_p·u_c uses the coverage factor k_p = 2 unless
the effective degrees of freedom (Welch–Satterthwaite, GUM G.4.1)

    ν_eff = u_c⁴ / Σ (c_i·u(x_i))⁴ / ν_i

are few enough that Student's t for 95.45 % coverage exceeds 2 (GUM G.3).
A Type B input (a certificate, a tolerance) has ν = ∞; a Type A one (the
fit's statistics, the repeatability of N releases) has its own.

An input whose standard uncertainty nobody stated is a line of the budget
with u = 0 and the note "not stated": the budget says what it does not know
rather than leaving it out silently.

The measurement model of a pendulum (SI units):

    ω = (ω_n + δω_fit + δω_model + δω_view + r_s·δs)·(1 + ε_R)·(1 + ε_clock)
    J = C / ω²,  C = k (torsion), m·g·S (compound) or m·g·R²/L (bifilar, trifilar)
    J_object = J − I0,  J_object_axis = J_object − m_o·L²

with δω_fit the fit's statistical error of ω_n, δω_model the model form (the
record's halves, rival models), δω_view the camera view's calibration, δs the
angle sensor's relative scale error (r_s = ∂ω_n/∂s from the fit's linear
response), ε_R the relative scatter between releases (reproducibility, ``measurement.reproducibility``)
and ε_clock the sample clock's relative frequency error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

from .errors import InvalidInput
from .wire import read_number

#: coverage probability of U (GUM 6.2: k = 2 ↔ 95.45 % for a normal distribution)
COVERAGE_PROBABILITY = 0.9545
#: the coverage factor of infinitely many degrees of freedom
DEFAULT_COVERAGE_FACTOR = 2.0

RANDOM, SYSTEMATIC = "random", "systematic"


class UncertaintyError(InvalidInput):
    """A stated uncertainty that cannot be used (negative, not a number, a covariance not PSD)."""


def check_std(name: str, value: Any, unit: str) -> float:
    """``value`` as a standard uncertainty (finite, >= 0), else one clear error."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise UncertaintyError(f"{name} must be a standard uncertainty in {unit} (a number >= 0), got {value!r}")
    if value < 0:
        raise UncertaintyError(f"{name} must be >= 0 {unit} (a standard uncertainty), got {value!r}")
    return float(value)


def check_covariance(name: str, cov: float, std_a: float | None, std_b: float | None) -> float:
    """A covariance of two inputs with the given σ; it must leave their 2×2 matrix positive semi-definite."""
    if isinstance(cov, bool) or not isinstance(cov, (int, float)) or not math.isfinite(float(cov)):
        raise UncertaintyError(f"{name} must be a number (a covariance), got {cov!r}")
    if std_a is None or std_b is None:
        raise UncertaintyError(f"{name} needs both standard uncertainties it relates")
    limit = std_a * std_b
    if abs(cov) > limit * (1 + 1e-9) + 1e-300:
        raise UncertaintyError(f"{name} = {cov:g} makes the covariance matrix not positive semi-definite: "
                               f"|covariance| must be <= σ·σ = {limit:g}")
    return float(cov)


def coverage_factor(dof: float, base: float = DEFAULT_COVERAGE_FACTOR) -> float:
    """k_p for ``dof`` effective degrees of freedom: Student's t at 95.45 %, never below ``base``."""
    if not math.isfinite(dof) or dof > 1e6:
        return base
    from scipy.special import stdtrit  # scipy.special: loaded by the fit anyway (scipy.stats is far heavier)

    return max(base, float(stdtrit(max(dof, 1.0), 0.5 + COVERAGE_PROBABILITY / 2)))


def welch_satterthwaite(u_c: float, terms: Sequence[tuple[float, float]]) -> float:
    """ν_eff from the combined u_c and each term's (contribution c_i·u_i, degrees of freedom ν_i)."""
    den = sum(c**4 / nu for c, nu in terms if math.isfinite(nu) and nu > 0 and c != 0)
    if den <= 0 or u_c <= 0:
        return math.inf
    return u_c**4 / den


@dataclass(frozen=True)
class Input:
    """One input quantity of the measurement model.

    symbol: its name in the model (a key of the function's argument). value, std: its estimate and
    standard uncertainty in ``unit`` (std None: nobody stated it; counted as 0 and said so).
    kind: "random" (changes from release to release: the fit, the model form) or "systematic"
    (common to every release: calibration, rig constants, clock). dof: degrees of freedom (∞: Type B).
    """

    symbol: str
    source: str
    value: float
    std: float | None
    unit: str
    kind: str = SYSTEMATIC
    dof: float = math.inf
    note: str = ""


@dataclass(frozen=True)
class Line:
    """One line of the budget: an input, its sensitivity and contribution c·u (in the measurand's unit)."""

    symbol: str
    source: str
    value: float
    std: float
    unit: str
    sensitivity: float
    contribution: float
    share: float
    kind: str
    dof: float
    stated: bool
    note: str

    def to_dict(self) -> dict[str, Any]:
        return {"symbol": self.symbol, "source": self.source, "value": _finite(self.value), "std": self.std,
                "unit": self.unit, "sensitivity": _finite(self.sensitivity), "contribution": self.contribution,
                "share": self.share, "kind": self.kind, "dof": _finite(self.dof), "stated": self.stated,
                "note": self.note}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Line:
        """Read back ``to_dict`` (null: a value or sensitivity that was not finite, NaN; dof ∞)."""
        return cls(d["symbol"], d["source"], read_number(d["value"]), read_number(d["std"]), d["unit"],
                   read_number(d["sensitivity"]), read_number(d["contribution"]), read_number(d["share"]), d["kind"],
                   _inf(d["dof"]), d["stated"], d["note"])


def _finite(v: float) -> float | None:
    return v if math.isfinite(v) else None


def _inf(v: float | None) -> float:
    """Degrees of freedom as written, ∞ where the JSON held null."""
    return math.inf if v is None else v


@dataclass(frozen=True)
class Budget:
    """The budget of one measurand: its lines, the correlation term and the expanded uncertainty.

    value, u, U: the measurand, its combined standard and expanded uncertainty (unit). share: each
    line's (c·u)²/u²; ``correlation_share`` the rest (2·Σ c_i c_j r_ij u_i u_j / u², may be < 0).
    u_random: the combined standard uncertainty of the random lines alone (they are uncorrelated with
    the rest), u_systematic = √(u² − u_random²).
    """

    measurand: str
    value: float
    unit: str
    lines: tuple[Line, ...]
    correlations: tuple[dict[str, Any], ...]
    correlation_share: float
    u: float
    u_random: float
    u_systematic: float
    dof: float
    coverage_factor: float
    U: float

    def to_dict(self) -> dict[str, Any]:
        return {"measurand": self.measurand, "value": self.value, "unit": self.unit,
                "lines": [ln.to_dict() for ln in self.lines], "correlations": [dict(c) for c in self.correlations],
                "correlation_share": self.correlation_share, "u": self.u, "u_random": self.u_random,
                "u_systematic": self.u_systematic, "dof": self.dof if self.dof < 1e6 else None,
                "coverage_factor": self.coverage_factor, "U": self.U}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Budget:
        """Read back ``to_dict`` (a result JSON's budget): dof null is ∞, another null a value that was not finite."""
        return cls(d["measurand"], read_number(d["value"]), d["unit"], tuple(Line.from_dict(ln) for ln in d["lines"]),
                   tuple(dict(c) for c in d["correlations"]), read_number(d["correlation_share"]), read_number(d["u"]),
                   read_number(d["u_random"]), read_number(d["u_systematic"]), _inf(d["dof"]),
                   read_number(d["coverage_factor"]), read_number(d["U"]))


def evaluate(measurand: str, unit: str, f: Callable[[Mapping[str, float]], float], inputs: Sequence[Input],
             correlations: Mapping[tuple[str, str], float] | None = None,
             base_coverage: float = DEFAULT_COVERAGE_FACTOR) -> Budget:
    """The GUM budget of y = f(inputs) (law of propagation of uncertainty, first order).

    Sensitivities are central differences with a step of 1e-4·u (1e-6 of the value's scale when u = 0),
    exact to a few ppm for the smooth models here. correlations: (symbol_a, symbol_b) → r.
    Inputs with no influence (c = 0) are left out.
    """
    x = {i.symbol: float(i.value) for i in inputs}
    y = float(f(x))
    cs: dict[str, float] = {}
    for i in inputs:
        u = i.std or 0.0
        # a step small against u (the model is smooth over ±u), never so small against the value that
        # round-off swamps it; an input with no u gets one of 1e-6 of its scale (1 for an error term at 0)
        h = max(1e-4 * u, 1e-9 * abs(i.value)) if u > 0 else 1e-6 * max(abs(i.value), 1.0)
        xp, xm = dict(x), dict(x)
        xp[i.symbol] += h
        xm[i.symbol] -= h
        cs[i.symbol] = (f(xp) - f(xm)) / (2 * h)
    used = [i for i in inputs if cs[i.symbol] != 0.0]  # an input f does not read has c = 0 exactly
    contrib = {i.symbol: cs[i.symbol] * (i.std or 0.0) + 0.0 for i in used}  # + 0.0: no −0 for a line not stated
    var_lines = sum(c**2 for c in contrib.values())
    cross = 0.0
    corr_out: list[dict[str, Any]] = []
    for (a, b), r in (correlations or {}).items():
        if a in contrib and b in contrib and r:
            cross += 2 * r * contrib[a] * contrib[b]
            corr_out.append({"a": a, "b": b, "r": float(r)})
    var = max(var_lines + cross, 0.0)
    u = math.sqrt(var)
    u_random = math.sqrt(sum(contrib[i.symbol] ** 2 for i in used if i.kind == RANDOM))
    u_sys = math.sqrt(max(var - u_random**2, 0.0))
    dof = welch_satterthwaite(u, [(contrib[i.symbol], i.dof) for i in used])
    k = coverage_factor(dof, base_coverage)
    lines = tuple(Line(i.symbol, i.source, float(i.value), float(i.std or 0.0), i.unit, float(cs[i.symbol]),
                       float(contrib[i.symbol]), float(contrib[i.symbol] ** 2 / var) if var > 0 else 0.0,
                       i.kind, float(i.dof), i.std is not None,
                       i.note or ("" if i.std is not None else "not stated: counted as 0"))
                  for i in used)
    return Budget(measurand, y, unit, lines, tuple(corr_out), cross / var if var > 0 else 0.0, u, u_random, u_sys,
                  dof, k, k * u)


# -- the pendulum's measurement model ------------------------------------------------------------

@dataclass(frozen=True)
class PendulumInputs:
    """Everything the budget of a pendulum's J needs (SI units; std None: not stated).

    omega_n: the identified ω_n (rad/s) with the fit's 1σ ``omega_n_std`` and its degrees of freedom;
    omega_n_model: model form 1σ (rad/s); omega_n_view: camera view calibration 1σ (rad/s).
    clock_ppm: the sample clock's standard uncertainty, ppm (None: not stated).
    angle_scale: (∂ω_n/∂s in rad/s per unit relative scale, 1σ of s) for a calibrated sensor, or None.
    rig_kind: "torsion" | "compound" | "bifilar" | "trifilar"; stiffness (N·m/rad) or mass (kg), com_distance
    (m) or wire_radius and wire_length (m, a wire suspension's R and L), g (m/s²), each with its std; tare (kg·m²) and std; cov_k_tare: covariance of k and I0 (N·m/rad·kg·m²).
    object_mass (kg), axis_offset (m) with stds for the parallel-axis transfer.
    """

    omega_n: float
    omega_n_std: float
    omega_n_dof: float = math.inf
    omega_n_model: float = 0.0
    omega_n_view: float | None = None
    clock_ppm: float | None = None
    angle_scale: tuple[float, float | None] | None = None
    rig_kind: str = "torsion"
    stiffness: float | None = None
    stiffness_std: float | None = None
    mass: float | None = None
    mass_std: float | None = None
    com_distance: float | None = None
    com_distance_std: float | None = None
    g: float | None = None
    g_std: float | None = None
    wire_radius: float | None = None
    wire_radius_std: float | None = None
    wire_length: float | None = None
    wire_length_std: float | None = None
    tare: float | None = None
    tare_std: float | None = None
    cov_k_tare: float | None = None
    object_mass: float | None = None
    object_mass_std: float | None = None
    axis_offset: float | None = None
    axis_offset_std: float | None = None
    #: between-release scatter of ω_n (``measurement.reproducibility``): (relative 1σ or None, ν, counted,
    #: note); None: no line (several releases carry their own scatter)
    reproducibility: tuple[float | None, float, bool, str] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def inputs(self) -> list[Input]:
        """The model's inputs, the not-stated ones included (u = 0, said so)."""
        out = [Input("omega_n_fit", "ω_n: fit (statistical)", self.omega_n, self.omega_n_std, "rad/s", RANDOM,
                     self.omega_n_dof)]
        if self.omega_n_model:
            out.append(Input("omega_n_model", "ω_n: model form", 0.0, self.omega_n_model, "rad/s", RANDOM,
                             note="halves of the record, rival models"))
        if self.reproducibility is not None:
            rel, dof, counted, note = self.reproducibility
            out.append(Input("omega_n_repro", "ω_n: reproducibility (relative)", 0.0, rel if counted else None, "1",
                             RANDOM, dof, note))
        if self.omega_n_view:
            out.append(Input("omega_n_view", "ω_n: camera view calibration", 0.0, self.omega_n_view, "rad/s"))
        out.append(Input("clock", "sample clock (relative)", 0.0,
                         None if self.clock_ppm is None else self.clock_ppm * 1e-6, "1"))
        if self.angle_scale is not None:
            out.append(Input("angle_scale", "angle sensor scale (relative)", 0.0, self.angle_scale[1], "1"))
        if self.rig_kind == "torsion":
            if self.stiffness is not None:
                out.append(Input("k", "stiffness k (calibration)", self.stiffness, self.stiffness_std, "N·m/rad"))
        elif self.wire_radius is not None and self.wire_length is not None:
            if self.mass is not None:
                out.append(Input("m", "hanging mass m", self.mass, self.mass_std, "kg"))
                out.append(Input("R", "wires' distance from the axis R", self.wire_radius, self.wire_radius_std, "m"))
                out.append(Input("Lw", "wire length L", self.wire_length, self.wire_length_std, "m"))
                out.append(Input("g", "local gravity g", self.g or 0.0, self.g_std, "m/s²"))
        else:
            if self.mass is not None and self.com_distance is not None:
                out.append(Input("m", "swinging mass m", self.mass, self.mass_std, "kg"))
                out.append(Input("S", "centre-of-mass distance S", self.com_distance, self.com_distance_std, "m"))
                out.append(Input("g", "local gravity g", self.g or 0.0, self.g_std, "m/s²"))
        if self.tare is not None:
            out.append(Input("I0", "tare inertia I0", self.tare, self.tare_std, "kg·m²"))
        if self.object_mass is not None and self.axis_offset is not None:
            out.append(Input("m_o", "object mass (axis transfer)", self.object_mass, self.object_mass_std, "kg"))
            out.append(Input("L", "object axis offset L", self.axis_offset, self.axis_offset_std, "m"))
        return out

    def correlations(self) -> dict[tuple[str, str], float]:
        if self.cov_k_tare and self.stiffness_std and self.tare_std:
            return {("k", "I0"): self.cov_k_tare / (self.stiffness_std * self.tare_std)}
        return {}

    def restoring(self, x: Mapping[str, float]) -> float | None:
        """C of J = C/ω² (N·m/rad or N·m), from the inputs."""
        if self.rig_kind == "torsion":
            return x.get("k", None)
        if "Lw" in x:
            return x["m"] * x["g"] * x["R"] ** 2 / x["Lw"]
        if "m" in x:
            return x["m"] * x["g"] * x["S"]
        return None

    def omega(self, x: Mapping[str, float]) -> float:
        """The true ω_n (rad/s) given the inputs' errors."""
        w = x["omega_n_fit"] + x.get("omega_n_model", 0.0) + x.get("omega_n_view", 0.0)
        if self.angle_scale is not None:
            w += self.angle_scale[0] * x["angle_scale"]
        return w * (1.0 + x.get("omega_n_repro", 0.0)) * (1.0 + x["clock"])

    def J(self, x: Mapping[str, float]) -> float:
        c = self.restoring(x)
        return math.nan if c is None else c / self.omega(x) ** 2

    def J_object(self, x: Mapping[str, float]) -> float:
        return self.J(x) - x["I0"]

    def J_object_axis(self, x: Mapping[str, float]) -> float:
        base = self.J_object(x) if "I0" in x else self.J(x)
        return base - x["m_o"] * x["L"] ** 2

    def budgets(self) -> dict[str, Budget]:
        """measurand → its budget: J (when the rig gives a restoring constant), J_object, J_object_axis."""
        inputs = self.inputs()
        x = {i.symbol: i.value for i in inputs}
        out: dict[str, Budget] = {}
        if self.restoring(x) is None:
            return out
        corr = self.correlations()
        out["J"] = evaluate("J", "kg·m²", self.J, inputs, corr)
        if "I0" in x:
            out["J_object"] = evaluate("J_object", "kg·m²", self.J_object, inputs, corr)
        if "m_o" in x:
            out["J_object_axis"] = evaluate("J_object_axis", "kg·m²", self.J_object_axis, inputs, corr)
        return out


# -- check standard ------------------------------------------------------------------------------

@dataclass(frozen=True)
class CheckStandard:
    """A reference artifact of certified J_ref ± U_ref measured as a part: does the budget hold?

    E_n = |J − J_ref| / √(U² + U_ref²) (ISO/IEC 17043:2010, "Conformity assessment — General
    requirements for proficiency testing", B.4.1.1): E_n ≤ 1 passes. A value far inside says the
    budget may be pessimistic; one beyond 1 says it is too small, or the rig has drifted. kg·m².
    """

    name: str
    quantity: str
    value: float
    U: float
    reference: float
    reference_U: float
    E_n: float
    passed: bool

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "quantity": self.quantity, "value": self.value, "U": self.U,
                "reference": self.reference, "reference_U": self.reference_U, "deviation": self.value - self.reference,
                "E_n": self.E_n, "passed": self.passed}


def check_standard(name: str, quantity: str, value: float, U: float, reference: float,
                   reference_U: float) -> CheckStandard:
    """The normalised error of a measured check standard against its certificate (kg·m²)."""
    for what, v in (("reference", reference), ("value", value)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise UncertaintyError(f"check standard: {what} must be a number in kg·m², got {v!r}")
    U = check_std("check standard: U", U, "kg·m²")
    reference_U = check_std("check standard: the reference's U", reference_U, "kg·m²")
    den = math.hypot(U, reference_U)
    if den == 0:
        raise UncertaintyError("check standard: U and the reference's U are both 0; expected an expanded uncertainty")
    e_n = abs(value - reference) / den
    return CheckStandard(name, quantity, float(value), U, float(reference), reference_U, e_n, e_n <= 1.0)
