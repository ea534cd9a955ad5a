"""Step 5, flags: the facts a reader must not miss, as the names of ``measurement.flags``.

Structure beyond the noise model is flagged (``unmodeled_residual``) when it
matters: it changes the answer by more than the fit's σ (the halves
disagree), or it has a shape the report can name, or the residual is so far
above the noise that the model misses the swing itself. A fit whose residual
is comparable to the swing does not follow it (``follows_swing``): it
carries ``fit_not_converged``, not structure left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import flags as F
from ..fit import ModelFit
from ..trace import READING_UNITS
from .discovery import SCREEN_TRUST
from .findings import Findings

#: residual RMS over the RMS of the fitted swing beyond which the model does not follow the swing (R² < 0.89);
#: the worst of the real records, a bifilar suspension whose restoring law no effect matches, stands at 0.16
FOLLOW_LIMIT = 1.0 / 3.0


def follows_swing(fit: ModelFit, sigma: float) -> tuple[bool, float]:
    """(whether the fitted model follows the swing, its residual RMS over the fitted swing's RMS).

    It does not when the residual is far above the noise floor (``SCREEN_TRUST``) and comparable to
    the swing itself (``FOLLOW_LIMIT``): whatever J such a fit implies, it is not read from the swing.
    """
    swing = float(np.sqrt(np.mean((fit.fitted - fit.value("offset")) ** 2)))
    ratio = fit.residual_rms / swing if swing > 0 else math.inf
    return not (fit.residual_rms > SCREEN_TRUST * sigma and ratio > FOLLOW_LIMIT), ratio


@dataclass(frozen=True)
class Leftover:
    """What the final residual holds beyond the noise model.

    named: its shapes the report can name; changes_answer: the halves disagree by more than the fit's
    σ; unmodeled: structure that matters and no library effect explains (flag unmodeled_residual).
    """

    structured: bool
    named: list[str]
    changes_answer: bool
    unmodeled: bool


def leftover(found: Findings) -> Leftover:
    """What the final residual of ``found`` holds, and whether it is flagged."""
    segments, diag, final, noise = found.segments, found.diag, found.final, found.prep.noise
    changes_answer = segments is not None and segments.disagree and segments.u > found.omega_n_std
    named = diag.named_structure(READING_UNITS[found.rig.measures])
    # far above the noise (where the loop's screen is not trusted either) a structured residual
    # is a model that misses the swing itself, whatever ω_n does
    far = noise > 0 and final.residual_rms > SCREEN_TRUST * noise
    # (a fit that does not follow the swing at all is a failed fit, not structure left: fit_not_converged)
    unmodeled = found.follows and diag.structured and (changes_answer or bool(named) or far)
    return Leftover(diag.structured, named, changes_answer, unmodeled)


def raise_flags(found: Findings, left: Leftover) -> tuple[str, ...]:
    """The result's flags: the acquisition's, then the identification's, each once, in that order."""
    final, prep, segments = found.final, found.prep, found.segments
    raised = [
        (left.unmodeled, F.UNMODELED_RESIDUAL),
        (segments is not None and segments.disagree, F.HALVES_DISAGREE),
        (found.ambiguous, F.MODEL_AMBIGUOUS),
        (found.n_outliers > 0, F.OUTLIERS_REMOVED),
        (final.n_downweighted > 0, F.OUTLIERS_DOWNWEIGHTED),
        (prep.gap_cut_at is not None, F.WINDOW_CUT_AT_GAP),
        (prep.n_unwrapped > 0, F.ANGLE_UNWRAPPED),
        (not final.success or not found.follows, F.FIT_NOT_CONVERGED),
        (any("." in n for n in final.at_bound), F.PARAMETER_AT_BOUND),  # an effect's, not the state's
        (final.cov_method != "white", F.CORRELATED_RESIDUAL),
        (found.inertias.negative, F.NEGATIVE_INERTIA),
        (found.nominal is not None, F.SENSOR_SCALE_FITTED),
    ]
    return tuple(dict.fromkeys(list(found.trace.flags) + [flag for holds, flag in raised if holds]))
