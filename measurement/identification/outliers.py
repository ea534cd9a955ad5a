"""Wild samples: those the pre-screen left, found in a model's residual and set aside.

Between the identification's passes (``without_wild``: isolated samples far
beyond the residual's robust σ, while a robust loss had to tame them) and once
on the final fit (``remove_outliers``: glitches judged in a residual that is
not itself structured).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..fit import ModelFit
from ..signal import robust_std
from ..trace import Trace
from .options import Options
from .preparation import Prepared


def departures(residual: np.ndarray, floor: float) -> tuple[np.ndarray, float]:
    """Each residual's distance from their median in robust σ, and that σ floored by ``floor`` (rad).

    outlier_sigma is read on this scale: the floor keeps a residual quieter than the noise (an
    encoder's steps) from making every sample an outlier.
    """
    scale = max(robust_std(residual), floor)
    return np.abs(residual - np.median(residual)) / scale, scale


def without_wild(fit: ModelFit, prep: Prepared, trace: Trace, options: Options) -> Prepared | None:
    """``prep`` without the isolated samples beyond outlier_sigma robust σ of ``fit``'s residual, or None if none is.

    The scale is floored by the robust noise floor, not the noise floor: that is itself raised by the very
    samples to be found.
    """
    r, _ = departures(fit.residual, prep.noise_robust)
    # isolated samples only: where the neighbours depart as well, the residual has a shape (a mode,
    # an effect the model lacks), and its peaks are not wild samples
    bound = np.maximum(options.outlier_sigma, r) / 2
    calm = np.r_[True, r[:-1] < bound[1:]] & np.r_[r[1:] < bound[:-1], True]
    wild = (r > options.outlier_sigma) & calm
    if not wild.any():
        return None
    keep = ~np.isin(prep.t, fit.t[wild])
    if keep.sum() < 30:
        return None
    found = np.searchsorted(trace.t, prep.t[~keep])
    return replace(prep, t=prep.t[keep], y=prep.y[keep], outliers=np.union1d(prep.outliers, found).astype(int))


def remove_outliers(fit: ModelFit, prep: Prepared, options: Options) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, angle) of ``fit``'s samples within outlier_sigma robust σ of its residual, and the indices of the others."""
    bad = departures(fit.residual, prep.noise)[0] > options.outlier_sigma
    return fit.t[~bad], fit.y[~bad], np.flatnonzero(bad)
