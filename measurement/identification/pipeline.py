"""The identification of one record, step by step (the package's doc lists the steps and their modules)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..consistency import check_segments
from ..diagnostics import diagnose
from ..effects import EFFECTS
from ..errors import RigError, UnknownEffectError
from ..fit import ModelFit, fit_model, with_score_floor
from ..model import Model
from ..reproducibility import for_release
from ..residual import Diagnostics
from ..result import DiscoveryStep, IdentificationResult
from ..rig import Rig
from ..trace import Trace
from .assembly import assemble
from .discovery import Move, discover
from .findings import Findings
from .flags import follows_swing, leftover, raise_flags
from .focus import DISCOVERED, Focus, focus
from .measurand import measurand, reference_amplitude
from .options import Options
from .outliers import departures, remove_outliers, without_wild
from .preparation import Prepared, prepare
from .quantities import inertias, omega_n_at_nominal_scale, omega_n_std_view
from .report import describe
from .rivals import Withdrawn, demanded_law, hold_across, law_rival, model_form
from .starts import Aliases, keep_nested_order, rival_frequencies
from .threads import one_blas_thread

#: identification passes on a record with wild samples: each sets aside those its model shows
CLEANING_PASSES = 3


def identify(trace: Trace, rig: Rig, options: Options = Options()) -> IdentificationResult:
    """Identify J, ω_n and the damping of ``trace`` on ``rig`` (see the package's doc)."""
    with one_blas_thread():
        return _identify(trace, rig, options)


class Diagnosis:
    """``diagnose`` of a fit with the record's noise floor, once per fit: the loop's last round may
    have diagnosed the final fit already."""

    def __init__(self, prep: Prepared) -> None:
        # the noise floor and whether the swing came to rest stay the same from pass to pass
        self.noise, self.stuck = prep.noise, prep.stuck
        self._done: dict[int, tuple[ModelFit, Diagnostics]] = {}  # by id, the fit kept so its id is not reused

    def __call__(self, fit: ModelFit) -> Diagnostics:
        if id(fit) not in self._done:
            self._done[id(fit)] = (fit, diagnose(fit, self.noise, self.stuck))
        return self._done[id(fit)][1]


def checked_inputs(trace: Trace, rig: Rig, options: Options) -> tuple[Rig, dict[str, Any] | None]:
    """The rig to identify on and the camera view measured on the record (None: none); raises
    UnknownEffectError for a candidate not in the library, RigError for a scale fitted twice."""
    if options.candidates is not None:
        unknown = [c for c in options.candidates if c not in EFFECTS]
        if unknown:
            raise UnknownEffectError(f"unknown candidate effect(s) {unknown}; expected names from {', '.join(EFFECTS)}")
    # a camera view measured on this record (two markers), with its 1σ: measurement.vision.marker_pair
    view = trace.meta.get("view") if isinstance(trace.meta.get("view"), dict) else None
    if view is not None and not rig.sensor_calibrated:
        # the camera's view was measured on this record: fitting the angle's scale again from the
        # swing would overrule the measurement with whatever the model lacks
        scaling = [n for n in rig.declared if n in EFFECTS and EFFECTS[n].scale_parameters]
        if scaling:
            raise RigError(f"{trace.source}: the camera's view was measured from the marker pair, but the rig declares "
                           f"{', '.join(scaling)}, which would fit the angle's scale again; drop it from [model] declared")
        rig = replace(rig, sensor_calibrated=True)
    if trace.quantity != rig.measures:
        # what the sensor reads is the trace's (an angle, or a gyro's rate): every model of this
        # identification reads it
        rig = replace(rig, measures=trace.quantity)
    return rig, view


@dataclass
class Passes:
    """Where the passes ended: the samples, the declared model's fit, the final model and how it was
    reached (steps, moves, the withdrawn effects, the sampling's aliases), the robust loss's scale
    (rad; None: least squares) and the simulations spent."""

    prep: Prepared
    base: ModelFit
    final: ModelFit
    aliases: Aliases
    f_scale: float | None
    steps: list[DiscoveryStep] = field(default_factory=list)
    moves: list[Move] = field(default_factory=list)
    withdrawn: Withdrawn | None = None
    nfev: int = 0


def baseline(declared: Model, prep: Prepared, options: Options) -> Passes:
    """Step 2: the declared model fitted to the whole record, from the swing's frequency and its aliases.

    Wild samples the pre-screen left (bursts, a stalled tracker) must not steer the fit or pass for an
    effect: with any beyond outlier_sigma robust σ of the declared model's residual, every fit uses a
    soft-L1 loss whose scale is set once here (one loss for all models keeps their BIC comparable).
    """
    base = fit_model(declared, prep.t, prep.y, prep.noise, swings=prep.swings)
    nfev = base.nfev
    aliases = rival_frequencies(base, prep.noise, options.bic_margin)
    base = aliases.fit
    nfev += aliases.spent
    f_scale = None
    far, scale = departures(base.residual, prep.noise)
    if np.any(far > options.outlier_sigma):
        f_scale = options.robust_scale * scale
        base = fit_model(declared, prep.t, prep.y, prep.noise, previous=base, f_scale=f_scale)
        nfev += base.nfev
    return Passes(prep, base, base, aliases, f_scale, nfev=nfev)


def run_passes(trace: Trace, rig: Rig, declared: Model, prep: Prepared, options: Options,
               diagnosis: Diagnosis) -> Passes:
    """Baseline, discovery and hold, pass after pass while wild samples are set aside.

    Samples that the robust loss had to tame (wild or mis-dated ones) still weigh in every model's BIC,
    where they drown an effect's evidence: once a pass has a model, those beyond outlier_sigma of its
    residual are set aside and the loop runs again (CLEANING_PASSES at most).
    """
    nfev = 0
    for last_pass in (k == CLEANING_PASSES - 1 for k in range(CLEANING_PASSES)):
        run = baseline(declared, prep, options)
        nfev += run.nfev
        if options.discover:
            found = discover(run.base, prep, rig, options, run.f_scale, diagnosis)
            nfev += found.spent
            run.final, run.withdrawn, spent = hold_across(found.final, run.base, found.moves, prep, rig, run.f_scale)
            run.steps, run.moves = found.steps, found.moves
            nfev += spent
            # a law the record does not determine, or one whose ω_n the halves contradict, is not added back
            if run.withdrawn is None or not any(EFFECTS[n].role == "stiffness" for n in run.withdrawn.effects):
                run.final, demanded, spent = demanded_law(run.final, prep, rig, run.f_scale, options.candidates)
                nfev += spent
                if demanded is not None:
                    step, move = demanded
                    run.steps.append(replace(step, round=len(run.steps) + 1))
                    run.moves.append(move)
        if last_pass or run.f_scale is None:
            break
        cleaner = without_wild(run.final, prep, trace, options)
        if cleaner is None:
            break
        prep = cleaner
    run.nfev = nfev
    return run


@dataclass
class Guarded:
    """The final fit once the glitches left in its residual are out and it is no worse than a model it
    contains; ``diag`` its diagnosis, the rest as ``Findings``."""

    base: ModelFit
    final: ModelFit
    diag: Diagnostics
    n_outliers: int
    slipped_from: ModelFit
    beaten_by: ModelFit | None
    nfev: int


def guard(run: Passes, options: Options, diagnosis: Diagnosis) -> Guarded:
    """Glitches the pre-screen missed, and the nested order of the models.

    Glitches show in the final residual; judged there because a structured baseline residual is not
    Gaussian. While the final residual is itself structured, its peaks are not glitches: the data are
    kept. Then never a model worse than one it contains: the declared model's fit and each step's on
    the same samples (``keep_nested_order``).
    """
    prep, final, base, nfev = run.prep, run.final, run.base, 0
    diag: Diagnostics = diagnosis(final)
    bad = np.zeros(0, dtype=int)
    if not diag.structured and run.f_scale is None:
        t_fit, y_fit, bad = remove_outliers(final, prep, options)
    n_outliers = prep.outliers.size + bad.size
    if bad.size:
        final = fit_model(final.model, t_fit, y_fit, prep.noise, previous=final)
        nfev += final.nfev
        if final.model.effect_names != base.model.effect_names:
            base = fit_model(base.model, t_fit, y_fit, prep.noise, previous=base)
            nfev += base.nfev
        else:
            base = final
        diag = diagnose(final, prep.noise, prep.stuck)
    slipped_from = final
    final, beaten_by, spent = keep_nested_order(final, [base] + [m.start for m in run.moves], prep.noise)
    nfev += spent
    if beaten_by is not None:
        diag = diagnose(final, prep.noise, prep.stuck)
    return Guarded(base, final, diag, n_outliers, slipped_from, beaten_by, nfev)


def _identify(trace: Trace, rig: Rig, options: Options) -> IdentificationResult:
    rig, view = checked_inputs(trace, rig, options)
    prep = prepare(trace, options)
    declared = Model.from_names(rig, rig.declared)
    diagnosis = Diagnosis(prep)
    run = run_passes(trace, rig, declared, prep, options, diagnosis)
    prep = run.prep
    g = guard(run, options, diagnosis)
    final = g.final
    follows, follow_ratio = follows_swing(final, prep.noise)
    # the model's form: does it hold across the record, and do rival models the data cannot
    # tell apart give another ω_n (consistency.py, rivals.py)
    at, basis = reference_amplitude(rig, final, options)
    segments = check_segments(final, prep.noise)
    law, spent = law_rival(final, run.moves, prep, rig, run.f_scale) if run.withdrawn is None else (None, 0)
    form = model_form(final, segments, run.steps, run.aliases, run.withdrawn, law, options.bic_margin,
                      options.rival_laws)
    # from the model whose ω_n is the more accurate where it is read (measurand.py, focus.py)
    head = (focus(final, g.base, form, prep.noise, run.aliases, follows_swing(g.base, prep.noise)[0], at)
            if options.focused else Focus(final, form, DISCOVERED, at=at))
    # the models chosen, the σ stated is no smaller than the record's own scores say (fit.py)
    floored = {id(f): with_score_floor(f) for f in (g.base, final, head.fit)}
    base, final = floored[id(g.base)], floored[id(final)]
    head = replace(head, fit=floored[id(head.fit)])
    w, ws, read = measurand(head.fit, at, basis)
    # a sensor calibrated from the record itself carries its own uncertainty into ω_n, beside the fit's
    w_cal = omega_n_std_view(head.fit, view) if view is not None else None
    found = Findings(
        trace=trace, rig=rig, prep=prep, declared=declared, base=base, final=final, steps=tuple(run.steps),
        withdrawn=run.withdrawn, law=law, segments=segments, form=form, diag=g.diag, n_outliers=g.n_outliers,
        slipped_from=g.slipped_from, beaten_by=g.beaten_by, follows=follows, follow_ratio=follow_ratio,
        view=view, omega_n_view=w_cal, inertias=inertias(rig, w, ws),
        nominal=omega_n_at_nominal_scale(final), nfev=run.nfev + g.nfev + spent, bic_margin=options.bic_margin,
        rival_laws=options.rival_laws, focus=head, read_at=read,
        reproducibility=options.reproducibility or for_release(None, rig.reproducibility))
    left = leftover(found)
    return assemble(found, raise_flags(found, left), describe(found, left))
