"""Starting values: where a fit starts decides which basin it ends in.

* ``rival_frequencies``: the declared model fitted from every frequency the
  samples may not tell from the swing's (a record with gaps has aliases);
  the best by BIC is kept, the others within the margin are rivals.
* ``keep_nested_order``: a final model that fits worse than a model it
  contains (the declared one, an earlier step) on the same samples left the
  optimum: it is refitted from that model's values (``nested_start``), or
  that model is kept.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np

from ..effects import EFFECTS
from ..errors import IdentificationError
from ..fit import ModelFit, fit_model
from ..model import Model
from ..result import Competitor
from ..starting import initial_guess


def contains(outer: Model, inner: Model) -> bool:
    """Whether ``outer`` holds every effect of ``inner``, itself or an effect that refines it (dahl for coulomb)."""
    names = set(outer.effect_names)
    refined = {EFFECTS[n].refines for n in names if n in EFFECTS}
    return all(n in names or n in refined for n in inner.effect_names)


def nested_start(model: Model, inner: ModelFit) -> np.ndarray:
    """The parameter vector of ``model`` whose swing is ``inner``'s: ``inner``'s values, every effect it lacks at
    its neutral 0, an effect that refines one of ``inner``'s at that one's values (``contains(model, inner.model)``)."""
    values: dict[str, list[float]] = {}
    for e in model.effects:
        if e.name in inner.model.layout:
            values[e.name] = inner.effect(e.name)
        elif e.refines is not None and e.refines in inner.model.layout:
            values[e.name] = inner.effect(e.refines) + [0.0] * (len(e.parameters) - 1)
    x = model.vector((inner.value("theta0"), inner.value("omega0"), inner.value("omega_n")), values,
                     inner.value("offset"))
    lo, hi = model.bounds()
    return np.clip(x, lo, hi)


#: n·ln(RSS / RSS of a model it contains) beyond which a fit is taken to have left the optimum (a likelihood
#: ratio of e^5): at its optimum a model fits the same samples at least as well as any model it contains
SLIP_MARGIN = 10.0
#: residual RMS over the RMS of the fitted swing beyond which the model does not follow the swing (R² < 0.89);


def _worse_than(fit: ModelFit, inner: ModelFit) -> bool:
    """``fit`` ends beyond ``SLIP_MARGIN`` worse than ``inner`` on the same samples."""
    return fit.n * math.log(max(fit.rss, 1e-300) / max(inner.rss, 1e-300)) > SLIP_MARGIN


def keep_nested_order(final: ModelFit, nested: Sequence[ModelFit], sigma: float
                      ) -> tuple[ModelFit, ModelFit | None, int]:
    """``final``, or, when a model it contains fits the very same samples much better (``SLIP_MARGIN``), the
    final model refitted from that fit's values, or that fit itself when the refit does not reach it.

    Adding an effect can never fit worse at the optimum; ending worse, a fit went down another basin (a
    refit after the outliers left, a start a cycle off over a long record) and would report a J from a
    model that does not follow the swing. sigma: the noise floor (rad). Returns (the fit to report, the
    contained fit that beat ``final`` or None, simulations spent).
    """
    same = [f for f in nested if f is not final and f.f_scale == final.f_scale and f.t.size == final.t.size
            and np.array_equal(f.t, final.t) and contains(final.model, f.model)]
    if not same:
        return final, None, 0
    best = min(same, key=lambda f: f.rss)
    if not _worse_than(final, best):
        return final, None, 0
    nfev = 0
    try:
        refit = fit_model(final.model, final.t, final.y, sigma, x0=nested_start(final.model, best),
                          scales=final.scales, previous=best, f_scale=final.f_scale)
        nfev = refit.nfev
        if not _worse_than(refit, best):
            return refit, best, nfev
    except IdentificationError:
        pass
    return best, best, nfev


class Aliases(NamedTuple):
    """The declared model's fit kept among the frequencies tried, the others the data do not separate
    from it (``Competitor``), the spread of their ω_n (rad/s) and the simulations spent."""

    fit: ModelFit
    rivals: tuple[Competitor, ...]
    u: float
    spent: int


def rival_frequencies(base: ModelFit, sigma: float, margin: float) -> Aliases:
    """The declared model fitted from each frequency the samples may not tell from the swing's.

    On a record with gaps (mostly silences, dense bursts between them) the sampling has its own
    quasi-period, and the swing's frequency shifted by it explains the samples nearly as well: the
    fit can settle on that alias. Each comparable periodogram peak (``Smoothed.peaks``) more than a
    peak's width from every fitted ω_n starts a fit of the same model; the best by BIC is kept
    (same parameters, so the lower residual), and the others within ``margin`` of it are rival
    explanations whose ω_n spread (BIC-weighted, as ``competitors``) enters ω_n's uncertainty.
    Returns the kept fit, the rivals, their spread (rad/s) and the evaluations spent.
    """
    smoothed = base.extra.get("smoothed")
    if smoothed is None or not smoothed.peaks:
        return Aliases(base, (), 0.0, 0)
    model = base.model
    width = 2 * math.pi / float(base.t[-1] - base.t[0])
    x_start, scales = initial_guess(model, base.t, base.y, sigma, smoothed)
    i_w = model.names.index("omega_n")
    lo, hi = model.bounds()
    fits = [base]
    spent = 0
    for w_alias in smoothed.peaks:
        if any(abs(w_alias - f.value("omega_n")) <= width for f in fits):
            continue
        x0 = x_start.copy()
        x0[i_w] = w_alias
        try:
            fit = fit_model(model, base.t, base.y, sigma, x0=np.clip(x0, lo, hi), scales=scales, f_scale=base.f_scale)
        except IdentificationError:
            continue
        spent += fit.nfev
        fit.extra["smoothed"] = smoothed
        fits.append(fit)
    kept = min(fits, key=lambda f: f.bic)
    w_kept = kept.value("omega_n")
    rivals = [f for f in fits if f is not kept and f.bic - kept.bic < margin and abs(f.value("omega_n") - w_kept) > width]
    if not rivals:
        return Aliases(kept, (), 0.0, spent)
    bics = np.array([kept.bic] + [f.bic for f in rivals])
    weights = np.exp(-(bics - bics.min()) / 2.0)
    weights /= weights.sum()
    out = tuple(Competitor(f"the swing at {f.value('omega_n'):.4g} rad/s, which the sampling's gaps do not tell from "
                           f"{w_kept:.4g} (an alias)", f.bic - kept.bic, float(wi), f.value("omega_n"),
                           f.value("omega_n") - w_kept) for f, wi in zip(rivals, weights[1:]))
    return Aliases(kept, out, math.sqrt(sum(c.weight * c.delta**2 for c in out)), spent)
