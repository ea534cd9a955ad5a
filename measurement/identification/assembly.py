"""Step 7, the result's assembly: the ``IdentificationResult`` from what the steps found."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..fit import swing_amplitude
from ..periods import Periods, periods
from ..result import IdentificationResult, Quantity
from .findings import Findings
from .measurand import read_at
from .quantities import (
    RATE_UNITS,
    budgets,
    damping_ratio,
    effect_quantities,
    model_summary,
    omega_at_amplitude,
    omega_n_per_scale,
)


def _statistics(found: Findings) -> dict[str, Any]:
    final, noise = found.final, found.prep.noise
    return {
        "n": final.n, "k": final.k, "dof": final.dof, "rss": final.rss,
        "chi2": final.rss / noise**2, "redchi": final.rss / noise**2 / max(final.dof, 1),
        "aic": final.aic, "bic": final.bic, "nfev": found.nfev, "success": final.success, "message": final.message,
        "covariance": final.cov_method, "covariance_inflation": final.cov_inflation,
        "noise_model_order": final.noise.order, "innovation_std": math.sqrt(final.noise.innovation_var),
        "robust_loss_scale": final.f_scale,
    }


def _window(found: Findings) -> dict[str, Any]:
    final, prep = found.final, found.prep
    return {
        "t_start": float(final.t[0]), "t_stop": float(final.t[-1]), "n_used": final.n, "n_total": len(found.trace),
        "n_outliers": found.n_outliers, "release_detected": prep.release_detected, "stop_detected": prep.stopped,
        "came_to_rest": prep.stuck, "n_downweighted": final.n_downweighted, "n_unwrapped": prep.n_unwrapped,
        "gap_cut_at": prep.gap_cut_at,
    }


def _arrays(found: Findings) -> dict[str, np.ndarray]:
    final, base, trace = found.final, found.base, found.trace
    return {
        "t": final.t, "angle": final.y, "fitted": final.fitted, "residual": final.residual,
        "baseline_fitted": base.fitted, "baseline_residual": base.residual,
        "trace_t": trace.t, "trace_angle": trace.angle,
    }


def _periods(found: Findings, w: float, w_u: float, zeta: float) -> Periods | None:
    final, rig = found.final, found.rig
    if not (math.isfinite(w) and w > 0):
        return None
    # the small-swing period is the final model's law's limit, carried to the headline read at an amplitude
    # (``measurand``; the declared model's where it is the more accurate)
    limit = w * found.omega_n / read_at(final, found.read_at.amplitude)[0]
    amplitude = swing_amplitude(final)
    at = omega_at_amplitude(final, amplitude)
    if at is not None:
        # the final model's amplitude law, carried to the headline's limit (the declared model's where it is
        # the more accurate: its law of amplitude is then the same, no restoring law having been added)
        at = (at[0] * limit / found.omega_n, *at[1:])
    swing = final.fitted - final.value("offset")
    return periods(rig.kind, limit, w_u * limit / w, limit if at is None else at[0], amplitude, zeta, final.t, swing,
                   rig.length, rig.length_std, rig.geometry)


def assemble(found: Findings, flags: tuple[str, ...], structure: tuple[str, ...]) -> IdentificationResult:
    """The result of one record: its quantities, uncertainty budgets, flags and sentences (``report``)."""
    final, rig, trace, head = found.final, found.rig, found.trace, found.headline
    form = head.form
    w, ws, w_cal, j = head.omega_n, head.omega_n_std, found.omega_n_view, found.inertias
    w_u = math.sqrt(ws**2 + (w_cal or 0.0) ** 2 + form.u**2)
    budget = budgets(rig, w, ws, dof=float(head.fit.dof), model=form.u, view=w_cal,
                     scale_response=omega_n_per_scale(head.fit) if rig.sensor_calibrated else None,
                     reproducibility=found.reproducibility)
    zeta, zeta_std, amp_ref = damping_ratio(final)
    return IdentificationResult(
        source=trace.source, rig_kind=rig.kind,
        J=j.J, J_std=j.J_std, J_object=j.J_object, J_object_std=j.J_object_std,
        J_object_axis=j.J_object_axis, J_object_axis_std=j.J_object_axis_std,
        omega_n=w, omega_n_std=ws, omega_n_std_calibration=w_cal, omega_n_std_model=form.u, omega_n_u=w_u,
        model_form=form,
        uncertainty_budget=budget, damping_ratio=zeta,
        damping_ratio_std=zeta_std, reference_amplitude=amp_ref,
        offset=Quantity(final.value("offset"), final.stdev("offset"), RATE_UNITS["rad"] if rig.measures == "rate" else "rad"),
        damping=effect_quantities(final, rig, ("damping",)),
        stiffness=effect_quantities(final, rig, ("stiffness",)),
        sensor=effect_quantities(final, rig, ("sensor",)),
        declared_effects=found.declared.effect_names, effects=final.model.effect_names,
        added_effects=tuple(n for n in final.model.effect_names if n not in found.declared.effect_names),
        residual_rms=final.residual_rms, noise_floor=found.prep.noise, statistics=_statistics(found), flags=flags,
        baseline=model_summary(found.base, rig), steps=found.steps, diagnostics=found.diag,
        structure=structure, window=_window(found), acquisition={k: v for k, v in trace.meta.items() if k != "truth"},
        sensor_calibrated=rig.sensor_calibrated, measures=rig.measures, arrays=_arrays(found),
        periods=_periods(found, w, w_u, zeta),
        omega_n_from=head.chosen, omega_n_effects=head.effects, reproducibility=found.reproducibility,
        omega_n_read_at=found.read_at,
    )
