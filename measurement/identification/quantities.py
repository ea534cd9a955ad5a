"""The quantities a fit implies: J from ω_n, each effect's physical values with their propagated σ,
the sensitivities of ω_n to the sensor's calibration, and the GUM budgets. Used by the single
record's assembly and by the joint fit of several releases alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Protocol, Sequence

import numpy as np

from ..effect_base import Effect
from ..fit import ModelFit, swing_amplitude
from ..model import Model
from ..reproducibility import Reproducibility
from ..result import ModelSummary, Quantity
from ..rig import Rig
from ..uncertainty import Budget, PendulumInputs


class FittedParameters(Protocol):
    """What ``effect_quantities`` reads of a fit: its model, parameter vector, covariance and 1σ."""

    @property
    def model(self) -> Model: ...

    @property
    def x(self) -> np.ndarray: ...

    @property
    def cov(self) -> np.ndarray: ...

    @property
    def std(self) -> np.ndarray: ...


def propagate(fn: Callable[[np.ndarray], float], x: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    """(fn(x), its 1σ) under the parameters' covariance, by central differences (first-order propagation)."""
    value = fn(x)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    g = np.zeros(x.size)
    for j in range(x.size):
        h = 1e-6 * max(abs(x[j]), std[j], 1e-12)
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        g[j] = (fn(xp) - fn(xm)) / (2 * h)
    return float(value), float(math.sqrt(max(float(g @ cov @ g), 0.0)))


def inertia(rig: Rig, omega_n: float) -> float | None:
    """J (kg·m²) from ω_n (rad/s): the rig's restoring constant over ω_n²; None when the rig gives none."""
    c = rig.restoring_constant
    return None if c is None else c / omega_n**2


def defined(value: float | None) -> float:
    """value as a float, NaN where it is undefined (None)."""
    return math.nan if value is None else float(value)


#: a sensor parameter's unit on an angle sensor → on a rate sensor
RATE_UNITS = {"rad": "rad/s", "rad/s": "rad/s²"}


def effect_quantities(fit: FittedParameters, rig: Rig, role: Sequence[str]) -> dict[str, dict[str, Quantity]]:
    """Effect → its fitted (normalised) and physical values with uncertainties, for effects of ``role``."""
    model, x, cov = fit.model, fit.x, fit.cov
    out: dict[str, dict[str, Quantity]] = {}
    for e in model.effects:
        if e.role not in role:
            continue
        sl = model.layout[e.name]
        params: dict[str, Quantity] = {}
        for p, v, s in zip(e.parameters, x[sl], fit.std[sl]):
            # a sensor term on a rate sensor acts on the rate: its unit is a time derivative's
            unit = RATE_UNITS.get(p.unit, p.unit) if e.role == "sensor" and rig.measures == "rate" else p.unit
            params[p.name] = Quantity(float(v), float(s), unit)

        def physical(xx: np.ndarray, _e: Effect = e) -> dict[str, float | None]:
            w = model.value(xx, "omega_n")
            return _e.physical(model.values(xx, _e.name), inertia(rig, w), w)

        for name, val in physical(x).items():
            if val is None:
                params[name] = Quantity(None, None, e.unit_of(name))
            else:
                # a quantity undefined beside x (Dahl's spring as θ_c crosses 0) has no uncertainty
                def one(xx: np.ndarray, _n: str = name) -> float:
                    return defined(physical(xx)[_n])

                v, s = propagate(one, x, cov)
                params[name] = Quantity(v, s, e.unit_of(name))
        out[e.name] = params
    return out


def model_summary(fit: ModelFit, rig: Rig) -> ModelSummary:
    """What one fitted model says (the declared model's, beside the final one in the report)."""
    w, ws = fit.value("omega_n"), fit.stdev("omega_n")
    J = inertia(rig, w)
    return ModelSummary(
        effects=fit.model.effect_names, J=J, J_std=None if J is None else 2 * J * ws / w,
        omega_n=w, omega_n_std=ws, residual_rms=fit.residual_rms, bic=fit.bic, aic=fit.aic,
        damping=effect_quantities(fit, rig, ("damping",)),
    )


def omega_n_at_nominal_scale(fit: ModelFit) -> tuple[list[str], float] | None:
    """ω_n (rad/s) the fit implies were the sensor's scale parameters at their nominal 0, and their names.

    The conditional mean under the fit's Gaussian uncertainty: ω_n − Σ_ωs·Σ_ss⁻¹·s.
    None when the model fits no scale.
    """
    model = fit.model
    names = [f"{e.name}.{p}" for e in model.sensor for p in e.scale_parameters]
    if not names:
        return None
    iw = model.index("omega_n")
    idx = [model.index(n) for n in names]
    s = fit.x[idx]
    cov_ss = fit.cov[np.ix_(idx, idx)]
    cov_ws = fit.cov[iw, idx]
    try:
        shift = float(cov_ws @ np.linalg.solve(cov_ss, s))
    except np.linalg.LinAlgError:
        return None
    return names, float(fit.x[iw]) - shift


def omega_n_std_view(fit: ModelFit, view: dict) -> float:
    """1σ of ω_n (rad/s) that the camera view's calibration carries into it.

    The angle was corrected for a view measured with 1σ stretch_std and shear_std; an error δ in
    them leaves δ·sin 2y and δ·cos 2y in the angle y, and the fit answers with its linear response
    (the least-squares pseudo-inverse of its Jacobian) to each.
    """
    y = fit.fitted
    errors = np.column_stack([np.sin(2 * y), np.cos(2 * y)])
    response = np.linalg.lstsq(fit.jac * fit.scales, errors, rcond=None)[0] * fit.scales[:, None]
    per_term = response[fit.model.index("omega_n")]
    return float(math.hypot(per_term[0] * view["stretch_std"], per_term[1] * view["shear_std"]))


def omega_n_per_scale(fit: ModelFit) -> float:
    """∂ω_n/∂s (rad/s per unit relative scale): how ω_n follows an angle read (1 + s) times too large.

    The fit's linear response (the least-squares pseudo-inverse of its Jacobian) to the error s·y it
    would see; zero for a linear restoring law, where the amplitude does not enter ω_n.
    """
    error = (fit.fitted - fit.value("offset"))[:, None]
    response = np.linalg.lstsq(fit.jac * fit.scales, error, rcond=None)[0] * fit.scales[:, None]
    return float(response[fit.model.index("omega_n"), 0])


def budgets(rig: Rig, omega_n: float, omega_n_std: float, *, dof: float = math.inf, model: float = 0.0,
            view: float | None = None, scale_response: float | None = None,
            reproducibility: Reproducibility | None = None) -> dict[str, Budget]:
    """The uncertainty budgets (measurand → ``Budget``) of a swing identified at ω_n ± σ on ``rig``.

    model, view: the model-form and camera-view 1σ of ω_n (rad/s); scale_response: ∂ω_n/∂s of the
    fit, for a sensor declared calibrated (its ``angle_scale_std`` then enters); reproducibility: the
    scatter between releases one release cannot see (None: no line, the releases carry their own).
    """
    obj = rig.object
    return PendulumInputs(
        reproducibility=None if reproducibility is None else (
            reproducibility.relative, reproducibility.dof, reproducibility.counted, reproducibility.note()),
        omega_n=omega_n, omega_n_std=omega_n_std, omega_n_dof=dof, omega_n_model=model, omega_n_view=view,
        clock_ppm=rig.clock_accuracy_ppm,
        angle_scale=None if scale_response is None else (scale_response, rig.angle_scale_std),
        rig_kind=rig.kind, stiffness=rig.stiffness, stiffness_std=rig.stiffness_std,
        mass=rig.mass, mass_std=rig.mass_std, com_distance=rig.com_distance, com_distance_std=rig.com_distance_std,
        g=rig.g, g_std=rig.g_std, wire_radius=rig.wire_radius, wire_radius_std=rig.wire_radius_std,
        wire_length=rig.wire_length, wire_length_std=rig.wire_length_std, tare=rig.tare_inertia, tare_std=rig.tare_inertia_std,
        cov_k_tare=rig.stiffness_tare_covariance,
        object_mass=None if obj is None else obj.mass, object_mass_std=None if obj is None else obj.mass_std,
        axis_offset=None if obj is None else obj.axis_offset, axis_offset_std=None if obj is None else obj.axis_offset_std,
    ).budgets()


@dataclass(frozen=True)
class Inertias:
    """J and what follows from it, kg·m² (None where the rig does not give it).

    J_std: the fit's 1σ; J_object: J − tare, J_object_axis: its parallel-axis transfer to the object's own
    axis, each with the σ of the fit and the tare. The calibration, the model form and the rest of J's
    uncertainty are its budget's (``budgets``), where the k–tare correlation is kept.
    """

    J: float | None
    J_std: float | None
    J_object: float | None
    J_object_std: float | None
    J_object_axis: float | None
    J_object_axis_std: float | None

    @property
    def negative(self) -> bool:
        """The object's J (after the tare or about its own axis) came out below 0."""
        return any(v is not None and v < 0 for v in (self.J_object, self.J_object_axis))


def inertias(rig: Rig, omega_n: float, omega_n_std: float) -> Inertias:
    """J and the object's J from ω_n ± the fit's 1σ (rad/s)."""
    w, ws = omega_n, omega_n_std
    J = inertia(rig, w)
    J_std = None if J is None else 2 * J * ws / w
    J_obj = J_obj_std = J_ax = J_ax_std = None
    if J is not None and rig.tare_inertia is not None:
        J_obj = J - rig.tare_inertia
        J_obj_std = math.hypot(J_std or 0.0, rig.tare_inertia_std or 0.0)
    if J is not None and rig.object is not None:
        base_j = J_obj if J_obj is not None else J
        J_ax = base_j - rig.object.mass * rig.object.axis_offset**2
        J_ax_std = J_obj_std if J_obj is not None else J_std
    return Inertias(J, J_std, J_obj, J_obj_std, J_ax, J_ax_std)


def omega_at_amplitude(fit: FittedParameters, amplitude: float) -> tuple[float, float] | None:
    """(ω, its 1σ) of the swing at ``amplitude`` (rad) by the fitted restoring laws, rad/s; None when no law
    of the model makes the frequency depend on the amplitude (then it is ω_n at every amplitude)."""
    model = fit.model
    laws = [e for e in model.dynamic if e.role == "stiffness"]
    if not laws:
        return None

    def omega(xx: np.ndarray) -> float:
        w2 = model.value(xx, "omega_n") ** 2 + sum(e.amplitude_stiffness(model.values(xx, e.name), amplitude)
                                                   for e in laws)
        return math.sqrt(max(w2, 0.0))

    return propagate(omega, fit.x, fit.cov)


def damping_ratio(fit: ModelFit) -> tuple[float, float, float]:
    """(ζ, its 1σ, the amplitude it is read at, rad): the equivalent viscous damping ratio of every
    dynamic effect at the fitted swing's largest amplitude."""
    model = fit.model
    amp_ref = swing_amplitude(fit)

    def ratio(xx: np.ndarray) -> float:
        w = model.value(xx, "omega_n")
        c_eq = sum(e.equivalent_viscous(model.values(xx, e.name), amp_ref, w) for e in model.dynamic)
        return c_eq / (2 * w)

    zeta, zeta_std = propagate(ratio, fit.x, fit.cov)
    return zeta, zeta_std, amp_ref
