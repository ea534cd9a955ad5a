"""Step 4c, where ω_n is read: one measurand for a torsion rig's calibration and its part.

On a torsion rig J = k/ω², and k comes from a calibration whose references
were swung at some amplitude: where the spring's stiffness changes with the
amplitude, k is the stiffness there, and J takes ω at the same amplitude.
A fitted amplitude law (a cubic spring the discovery loop added, not a rig's
exact geometry law: a compound pendulum's sin θ and a wire suspension's law
stay as they are, and ω_n is their small-swing limit) is therefore not
extrapolated to zero amplitude, where the record holds no swing and the
fitted law's value scatters from release to release (the front wheel on the
bicycle set's torsion rod: a cubic spring whose sign flips between releases
moved the small-swing limit 0.5 % apart). ω is read at the reference amplitude:

    the amplitude the rig's calibration read its references at (``[calibration] amplitude``),
    else the record's own: the amplitude a damped sinusoid fitted to it measures at.

A damped sinusoid fitted to a swing whose frequency drifts with its envelope
A(t) measures a weighted mean of the frequency: to first order in the phase
error, least squares regresses the swing's phase on time with weights A², and
the slope of that regression is the mean of ω(t) under the kernel
K(s) = Σ_{t>s} A²(t)·(t − t̄) / Σ A²·(t − t̄)² (≥ 0, integrating to 1). Since
ω² moves with A² (a cubic spring's describing function), the plain fit reads
the frequency at A_ref² = ∫K·A² ds: ``record_amplitude``. The declared
model's ω_n is then the same measurand as the discovered model's ω at A_ref,
and the focused choice (``focus``) can weigh them.
"""

from __future__ import annotations

import math

import numpy as np

from ..fit import ModelFit
from ..result import CALIBRATION, LIMIT, RECORD, ReadAt
from ..rig import Rig
from .options import Options
from .quantities import FittedParameters, omega_at_amplitude


def record_amplitude(fit: ModelFit) -> float:
    """The amplitude (rad) at which a damped sinusoid fitted to ``fit``'s record measures the frequency (module
    doc): the swing's squared envelope θ² + (θ'/ω_n)² averaged under the phase regression's kernel."""
    t = np.asarray(fit.t, dtype=float)
    theta, rate = np.asarray(fit.extra["theta"], dtype=float), np.asarray(fit.extra["omega"], dtype=float)
    a2 = theta**2 + (rate / max(fit.value("omega_n"), 1e-12)) ** 2
    if t.size < 3 or not np.any(a2 > 0):
        return float(math.sqrt(float(np.max(a2, initial=0.0))))
    t_bar = float(np.sum(a2 * t) / np.sum(a2))
    c = a2 * (t - t_bar)
    # K at each sample: the weighted lever of every later sample; dt its share of the time axis
    kernel = np.concatenate([np.cumsum(c[::-1])[::-1][1:], [0.0]])
    dt = np.gradient(t)
    weight = np.clip(kernel, 0.0, None) * dt
    if not np.sum(weight) > 0:
        return float(math.sqrt(float(np.mean(a2))))
    return float(math.sqrt(float(np.sum(weight * a2) / np.sum(weight))))


def reference_amplitude(rig: Rig, final: ModelFit, options: Options) -> tuple[float, str]:
    """(the amplitude ω_n is read at, rad; its basis): on a torsion rig the one ``options`` names, else the
    calibration's, else the record's own (``record_amplitude`` of the final fit); elsewhere the small-swing limit."""
    if rig.kind != "torsion":
        return 0.0, LIMIT
    if options.reference_amplitude is not None:
        return float(options.reference_amplitude), options.reference_basis
    if rig.calibration is not None and rig.calibration.amplitude is not None:
        return float(rig.calibration.amplitude), CALIBRATION
    return record_amplitude(final), RECORD


def read_at(fit: FittedParameters, amplitude: float) -> tuple[float, float]:
    """(ω, its 1σ) of ``fit`` at ``amplitude`` (rad) by its fitted amplitude laws, rad/s; its ω_n where it has
    none or the amplitude is 0 (the small-swing limit)."""
    at = omega_at_amplitude(fit, amplitude) if amplitude > 0 else None
    if at is not None:
        return at
    i = fit.model.index("omega_n")
    return float(fit.x[i]), float(math.sqrt(max(float(fit.cov[i, i]), 0.0)))


def has_law(fit: FittedParameters) -> bool:
    """The fit holds a fitted amplitude law (a restoring law of role "stiffness")."""
    return any(e.role == "stiffness" for e in fit.model.dynamic)


def measurand(fit: ModelFit, amplitude: float, basis: str) -> tuple[float, float, ReadAt]:
    """(ω, its 1σ, where it is read) of the headline ``fit``: at ``amplitude`` where a fitted law makes it
    depend on the amplitude, with the law's small-swing limit beside it."""
    w, s = read_at(fit, amplitude)
    if basis == LIMIT or amplitude <= 0 or not has_law(fit):
        return w, s, ReadAt(amplitude, basis)
    return w, s, ReadAt(amplitude, basis, fit.value("omega_n"), fit.stdev("omega_n"))
