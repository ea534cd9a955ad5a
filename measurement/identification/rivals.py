"""Step 4, rivals and the model's form: models the data do not decisively separate from the one kept.

    hold  → an effect that moved ω_n by more than its σ is withdrawn when the
            model it ends in gives another ω_n in each half of the record
            (and no closer one than without it), or when it is a restoring
            law the record does not determine (``hold_across``); its ω_n
            stays a rival in the uncertainty
    halves → a restoring law the loop offers but did not add is added where
            the kept model's halves disagree and the law makes them agree
            and is determined by the record (``demanded_law``)
    law   → an effect that mimics a restoring law the rig does not offer
            (Dahl's pre-sliding spring, a sensor's fitted scale) is fitted with
            the law in its place (``law_rival``); its BIC weight says whether
            the data separate them
    form  → the record's halves, the discovery's near rivals, the sampling's
            aliases, the withdrawn model and the law, as one ``ModelForm``
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..consistency import bic_weights, check_segments, competitors
from ..effects import EFFECTS, candidate_effects, resolve_effects, unweighed_law, with_effect
from ..errors import IdentificationError
from ..fit import ModelFit, fit_model, swing_amplitude
from ..model import Model
from ..result import Competitor, DiscoveryStep, ModelForm, SegmentCheck
from ..rig import Rig
from .discovery import Move
from .preparation import Prepared
from .starts import Aliases


@dataclass(frozen=True)
class Withdrawn:
    """Effects taken back because the ω_n they moved does not hold across the record.

    effects: the effects withdrawn; omega_n: the model's with them (rad/s);
    d_bic: its BIC minus the kept model's; segments: its halves (None: the record is too short to split);
    model_effects: that model's effects; undetermined: where the withdrawn effect is a restoring law the
    record does not determine, its parameter (name, value, 1σ), else None.
    """

    effects: tuple[str, ...]
    omega_n: float
    omega_n_std: float
    d_bic: float
    segments: SegmentCheck | None
    model_effects: tuple[str, ...]
    undetermined: tuple[str, float, float] | None = None

    def rival(self, kept_omega_n: float) -> Competitor:
        """This model as a rival of the kept one of ω_n ``kept_omega_n`` (rad/s), carried whole."""
        why = ("the record does not determine it" if self.undetermined is not None else
               "the ω_n it moves does not hold across the record")
        return Competitor(f"{', '.join(self.effects)} kept ({why})",
                          self.d_bic, 1.0, self.omega_n, self.omega_n - kept_omega_n, self.model_effects)


#: a restoring law that moves ω_n is kept only where the record determines it: each parameter this many σ from 0
LAW_SIGMA = 3.0
#: a model whose halves disagree still explains them when its halves' z is at most this share of the z of
#: the model without its movers (a law that turns 53 σ of disagreement into 2.6 σ has explained something)
EXPLAINED_SHARE = 0.25


def undetermined_law(fit: ModelFit, names: Sequence[str]) -> tuple[str, float, float] | None:
    """The first parameter of a restoring law among ``names`` less than LAW_SIGMA σ from zero in ``fit``:
    (its name, value, 1σ); None when every one is determined."""
    for n in names:
        if EFFECTS[n].role != "stiffness":
            continue
        for q in EFFECTS[n].parameters:
            name = f"{n}.{q.name}"
            value, std = fit.value(name), fit.stdev(name)
            if not abs(value) >= LAW_SIGMA * std:
                return name, value, std
    return None


def fallback(names: Sequence[str], taken: Sequence[str], moves: Sequence[Move]) -> tuple[list[str], ModelFit | None]:
    """The effect names without ``taken``, each one's refined effect (Coulomb for Dahl) in its place, and
    the loop's last fit within them (the model itself, or a start that it contains; None: none)."""
    keep = [n for n in names if n not in taken]
    keep += [r for n in taken if (r := EFFECTS[n].refines) is not None and r not in keep]
    earlier = [m.start for m in moves if set(m.start.model.effect_names) <= set(keep)]
    return keep, (earlier[-1] if earlier else None)


def hold_across(final: ModelFit, base: ModelFit, moves: Sequence[Move], prep: Prepared,
                rig: Rig, f_scale: float | None) -> tuple[ModelFit, Withdrawn | None, int]:
    """The final model, or the one without the effects whose ω_n does not hold across the record.

    An effect that moved ω_n by more than its σ when it was added (``moves``)
    stands only if the model it ends in holds across the record: the same
    ω_n from both halves (``check_segments``). BIC alone cannot show it: an
    effect that mimics a restoring law the model lacks (pre-sliding
    friction's spring at small amplitude for a law softer than sin θ, a
    cubic spring for a frequency that drifts with time) lowers it as much as
    a true one. The model, not each effect, is judged, and on ω_n, not on
    every parameter: a friction law fitted to half a record legitimately
    differs from the whole's, and on the way to a law that holds (Coulomb,
    then Dahl friction) the intermediate models need not hold. Withdrawn,
    an effect that refines another (dahl, coulomb) falls back to it; the
    withdrawn model's ω_n stays a rival in the uncertainty (consistency.py).
    Halves that disagree still keep a restoring law (role "stiffness") where
    they disagree far more without it (``EXPLAINED_SHARE``): the law has
    explained something, and what is left enters u through the halves. A restoring
    law (a cubic spring) that moved ω_n must also be determined by the
    record, each of its parameters ``LAW_SIGMA`` σ from zero under the
    residual's noise model: a slow line in the sensor or a drifting zero
    buys a law that lowers BIC while its own value is barely told from zero.
    Returns (fit, what was withdrawn or None, simulations spent).
    """
    names = final.model.effect_names
    movers = [m.effect for m in moves if m.moved and m.effect in names and not EFFECTS[m.effect].scale_parameters]
    w = final.value("omega_n")
    if not movers or abs(w - base.value("omega_n")) <= final.stdev("omega_n"):
        return final, None, 0
    undetermined = undetermined_law(final, movers)
    seg = check_segments(final, prep.noise)
    if undetermined is None and (seg is None or not seg.disagree):
        return final, None, 0
    taken = [undetermined[0].split(".")[0]] if undetermined is not None else movers
    keep, earlier = fallback(names, taken, moves)
    model = Model(rig, tuple(resolve_effects(keep, rig)))
    previous = earlier or base
    nfev = 0
    if previous.model.effect_names != model.effect_names:
        try:
            previous = fit_model(model, final.t, final.y, prep.noise, previous=previous, f_scale=f_scale)
        except IdentificationError:
            return final, None, 0
        nfev = previous.nfev
    if undetermined is None and seg is not None and all(EFFECTS[n].role == "stiffness" for n in taken):
        # a restoring law explains the halves where they disagree far more without it; an effect that
        # mimics one (Dahl's pre-sliding spring) brings them closer without being the law
        without = check_segments(previous, prep.noise)
        if without is not None and without.disagree and seg.z <= EXPLAINED_SHARE * without.z:
            return final, None, nfev
    return previous, Withdrawn(tuple(taken), w, final.stdev("omega_n"), final.bic - previous.bic, seg,
                               final.model.effect_names, undetermined), nfev


def demanded_law(final: ModelFit, prep: Prepared, rig: Rig, f_scale: float | None,
                 allowed: Sequence[str] | None = None) -> tuple[ModelFit, tuple[DiscoveryStep, Move] | None, int]:
    """``final``, or ``final`` with the restoring law its halves demand where BIC did not add it.

    The converse of the rule that keeps a law in ``hold_across``: where the
    kept model's halves disagree (its ω_n does not hold across the record)
    and a restoring law the loop offers on this rig brings their z down to
    ``EXPLAINED_SHARE`` of it or less, determined by the record (each
    parameter ``LAW_SIGMA`` σ from 0), the law is added. BIC may not have
    added it: each model's BIC is read under its own AR noise model, and the
    kept model's, fitted to a residual that is the smooth error of a missing
    law, predicts that error and scores it as noise (a torsion rod read as an
    angle: the residual 8.4e-4 rad, 1700 times the noise floor, its AR(12)
    innovations 7.4e-6 rad; with the rod's softening spring the residual
    falls to 3.4e-4 rad, its halves from z 23 to 2.5, and BIC still rises).
    Releases of one object then read one measurand, the law's small-swing
    limit, not the law in one release and the frequency at the swing in the
    next. allowed: the candidates the loop may add (None: all). Returns (the
    fit, (the round's record, the move) or None, simulations spent).
    """
    seg = check_segments(final, prep.noise)
    if seg is None or not seg.disagree:
        return final, None, 0
    amplitude = swing_amplitude(final)
    laws = [e for e in candidate_effects(rig, final.model.effect_names)
            if e.role == "stiffness" and (allowed is None or e.name in allowed) and e.identifiable(amplitude)]
    nfev = 0
    for law in laws:
        model = Model(rig, tuple(resolve_effects(with_effect(final.model.effect_names, law), rig)))
        try:
            fit = fit_model(model, final.t, final.y, prep.noise, previous=final, f_scale=f_scale)
        except IdentificationError:
            continue
        nfev += fit.nfev
        with_law = check_segments(fit, prep.noise)
        if (with_law is None or with_law.z > EXPLAINED_SHARE * seg.z or fit.rss >= final.rss
                or undetermined_law(fit, [law.name]) is not None):
            continue
        w, w_fit = final.value("omega_n"), fit.value("omega_n")
        step = DiscoveryStep(
            0, final.residual_rms, final.bic,
            {law.name: {"bic": fit.bic, "residual_rms": fit.residual_rms, "omega_n": w_fit}}, law.name,
            fit.residual_rms, fit.bic, "",
            f"the record's halves demand it: without it their ω_n disagree (z {seg.z:.1f}), with it z "
            f"{with_law.z:.1f}; BIC {fit.bic - final.bic:+.1f}, each model under its own AR noise model", w)
        return fit, (step, Move(law.name, w_fit - w, fit.stdev("omega_n"), final)), nfev
    return final, None, nfev


@dataclass(frozen=True)
class LawRival:
    """A restoring law the loop does not offer on this rig, fitted in place of an effect that mimics it.

    effect: the kept effects that stand for it, comma-separated (dahl; gain, view); law: the law's
    effect (cubic_stiffness);
    omega_n: ω_n of the model with the law instead (rad/s); d_bic: that model's BIC minus the kept
    one's; weight: its BIC weight against the kept model; model_effects: that model's effects.
    """

    effect: str
    law: str
    omega_n: float
    d_bic: float
    weight: float
    model_effects: tuple[str, ...]

    def rival(self, kept_omega_n: float) -> Competitor:
        """This model as a rival of the kept one of ω_n ``kept_omega_n`` (rad/s), by its BIC weight."""
        return Competitor(f"{self.law} (a restoring law, not offered on this rig) instead of {self.effect}",
                          self.d_bic, self.weight, self.omega_n, self.omega_n - kept_omega_n, self.model_effects)


def law_rival(final: ModelFit, moves: Sequence[Move], prep: Prepared, rig: Rig,
              f_scale: float | None) -> tuple[LawRival | None, int]:
    """The restoring law that a kept effect may stand for, fitted in its place as a rival model.

    Dahl's pre-sliding spring makes the small swings faster; so does a
    restoring law softer than m·g·S·sin θ at large angles (a bifilar
    suspension, a cable), and the two read ω_n on opposite sides: the
    spring's ω_n is the large swings' law with a spring added at small
    amplitude, the law's is the small-swing limit. The loop does not offer
    such a law on a compound rig (there it would stand for friction it
    cannot tell from), so it never weighs it. Where an effect that mimics a
    law (``Effect.mimics``) moved ω_n by more than its σ when it was added
    (``moves``) and the law is not offered, the model with the law in the
    effect's place (and the effect it refines: Coulomb for Dahl) is fitted;
    its BIC weight against the kept model says whether the data separate
    them. A sensor's fitted scale (gain, view's stretch) changes how the
    frequency depends on the amplitude as such a law does, and gives way to
    it the same way. Returns (the rival or None, simulations spent).
    """
    names = final.model.effect_names
    mimics = [law for m in moves if m.effect in names and m.moved
              and (law := unweighed_law(EFFECTS[m.effect], rig.kind)) is not None and law not in names]
    if not mimics:
        return None, 0
    law = mimics[-1]
    # every kept effect that stands for the same law gives way to it (a sensor's gain and view both)
    taken = [n for n in names if EFFECTS[n].mimics == law]
    keep, earlier = fallback(names, taken, moves)
    model = Model(rig, tuple(resolve_effects(keep + [law], rig)))
    try:
        fit = fit_model(model, final.t, final.y, prep.noise, previous=earlier or final, f_scale=f_scale)
    except IdentificationError:
        return None, 0
    d_bic = fit.bic - final.bic
    weight = float(bic_weights(np.array([final.bic, fit.bic]))[1])
    return LawRival(", ".join(taken), law, fit.value("omega_n"), d_bic, weight, model.effect_names), fit.nfev


def model_form(final: ModelFit, segments: SegmentCheck | None, steps: Sequence[DiscoveryStep], aliases: Aliases,
               withdrawn: Withdrawn | None, law: LawRival | None, margin: float,
               rival_laws: Sequence[tuple[str, float, tuple[str, ...], str]] = ()) -> ModelForm:
    """The model-form part of ``final``'s ω_n uncertainty (``result.ModelForm``).

    Its halves (``check_segments``), the discovery's rounds' near rivals (``competitors``), the
    sampling's aliases, the withdrawn model (its distance carried whole: BIC prefers it, the halves
    contradict it), the law in a mimicking effect's place (by its BIC weight, when within ``margin``)
    and the laws the releases of the object withdrew together (``Options.rival_laws``, carried whole).
    """
    w = final.value("omega_n")
    rivals, u_rivals = competitors(steps, margin)
    if aliases.rivals:
        rivals += aliases.rivals
        u_rivals = math.hypot(u_rivals, aliases.u)
    if withdrawn is not None:
        rival = withdrawn.rival(w)
        rivals += (rival,)
        u_rivals = math.hypot(u_rivals, rival.delta)
    if law is not None and law.d_bic < margin:
        rival = law.rival(w)
        rivals += (rival,)
        u_rivals = math.hypot(u_rivals, math.sqrt(rival.weight) * rival.delta)
    for name, w_law, effects, _ in rival_laws:
        rivals += (Competitor(f"{name} kept (not a law of the object: its releases do not agree on it)",
                              0.0, 1.0, w_law, w_law - w, effects),)
        u_rivals = math.hypot(u_rivals, w_law - w)
    return ModelForm(segments, rivals, covering(u_rivals, rivals, final.stdev("omega_n")))


#: coverage factor within whose expanded uncertainty every rival of an ambiguous ω_n lies
COVER_K = 2.0


def covering(u_rivals: float, rivals: Sequence[Competitor], omega_n_std: float) -> float:
    """The rivals' term of u (rad/s), widened where they make ω_n ambiguous so that each lies within COVER_K u.

    A rival's BIC weight spreads ω_n by √w·|Δ| (Burnham and Anderson's model-averaged variance). Where
    that spread is beyond the fit's σ (``ModelForm.ambiguous``: the data do not decide between the
    models), a rival of small weight far away is still a model the data allow: its ω_n is a value the
    answer may be, so the answer's expanded uncertainty must reach it, not a confident number many of
    its u away from a model it names.
    """
    if u_rivals <= omega_n_std or not rivals:
        return u_rivals
    return max(u_rivals, max(abs(c.delta) for c in rivals) / COVER_K)
