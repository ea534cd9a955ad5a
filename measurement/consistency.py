"""Does the identified model hold across the record, and could another model explain it as well?

A low residual on one record is not how a model is shown true: the same
physics must give the same answer wherever it is looked at. Two checks turn
that into an uncertainty of the model's form, beside the fit's statistical σ:

* **Segments.** The final model is fitted again to each half of the record
  (started from the whole fit, each half with its own initial state and
  sensor zero). A model that holds gives the same ω_n in both halves within
  their σ; a model that lacks an amplitude- or time-dependent effect does
  not, and the whole-record value then lies wherever the compromise of its
  errors put it. The scatter of the halves about the whole, beyond what
  their σ explain, is a variance component of the model's form (a
  method-of-moments estimate, as DerSimonian and Laird estimate the
  between-study variance in "Meta-analysis in clinical trials", 1986). It
  rests on one comparison: a transient of the release in the first half
  (a hand still touching, a sensor settling) can move that half's ω_n onto
  the second's and hide a model that does not hold, so the first half is
  fitted again without its first half-swing and the larger term is kept.
* **Competing explanations.** Where the discovery loop found models within
  its BIC margin of the one it kept (another effect that explains the same
  residual, or an effect not quite worth adding), the data do not
  decisively separate them: their spread of ω_n, weighted by their BIC
  weights (Burnham and Anderson, "Model Selection and Multimodel Inference",
  ch. 4), is carried into the uncertainty and the models are named.

What they find is plain data the result carries (``result.SegmentCheck``,
``result.Competitor``, ``result.ModelForm``).

A sensor-scale effect that moves ω_n by more than its own σ must also hold
across the record: its parameters fitted in each half must agree
(``effect_holds``), so that a sensor scale that is really an approximate
restoring law is not bought with a wrong J. A damping or stiffness effect
that moves ω_n is judged on ω_n alone: the model it ends in must give the
same ω_n from both halves (``identification.rivals.hold_across``).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from scipy.special import erfc, gammaincc

from .errors import IdentificationError
from .fit import ModelFit, fit_model
from .result import Competitor, SegmentCheck

#: fewest full swings a segment must hold to be fitted on its own
MIN_SEGMENT_SWINGS = 3.0
#: p-value below which an effect's parameters fitted in the two halves disagree
EFFECT_P = 1e-3
#: largest leverage of the zero-amplitude extrapolation through the halves (m₂/(m₁ − m₂), m the
#: halves' mean square angle): 2 where the second half's is a third of the first's
MAX_LEVERAGE = 2.0


def _swings_in(theta: np.ndarray) -> float:
    """Full swings in a stretch of the true angle (zero crossings / 2)."""
    s = np.signbit(theta)
    return float(np.count_nonzero(s[1:] != s[:-1])) / 2.0


def halves(fit: ModelFit) -> tuple[slice, slice] | None:
    """The two halves of the fitted samples, or None when either holds too few swings to be fitted alone."""
    n = fit.n
    cut = n // 2
    theta = fit.extra["theta"]
    first, second = slice(0, cut), slice(cut, n)
    if min(_swings_in(theta[first]), _swings_in(theta[second])) < MIN_SEGMENT_SWINGS or min(cut, n - cut) < 30:
        return None
    return first, second


def refit_segment(fit: ModelFit, part: slice, sigma: float) -> ModelFit:
    """``fit``'s model refitted to the samples in ``part`` alone, started from ``fit``.

    The initial state is the whole fit's swing at the segment's first sample;
    the linear sensor terms (offset, drift...) start from their least-squares
    values on the segment given that swing.
    """
    model = fit.model
    t, y = fit.t[part], fit.y[part]
    theta, omega = fit.extra["theta"][part], fit.extra["omega"][part]
    x0 = fit.x.copy()
    x0[model.index("theta0")] = float(theta[0])
    x0[model.index("omega0")] = float(omega[0])
    reading = model.reading(theta, omega)
    x0[model.n_dynamic:], *_ = np.linalg.lstsq(model.sensor_columns(t - t[0], reading), y - reading, rcond=None)
    lo, hi = model.bounds()
    return fit_model(model, t, y, sigma, x0=np.clip(x0, lo, hi), scales=fit.scales, max_step=fit.max_step,
                     f_scale=fit.f_scale)


def segment_fits(fit: ModelFit, sigma: float) -> tuple[float, list[ModelFit]] | None:
    """(time of the split, the fits of both halves); None when the record is too short to split or a
    half cannot be fitted alone."""
    parts = halves(fit)
    if parts is None:
        return None
    try:
        return float(fit.t[parts[1].start]), [refit_segment(fit, p, sigma) for p in parts]
    except IdentificationError:
        return None


def check_segments(fit: ModelFit, sigma: float) -> SegmentCheck | None:
    """ω_n of each half against the whole record's (None when the record cannot be split).

    The model-form uncertainty u is the larger of two method-of-moments
    estimates (each the squared deviation less what the halves' σ explain):
    the halves' scatter about the whole, and the distance from the whole to
    ω_n extrapolated to zero amplitude along the line through the halves'
    values against their mean square angle. A restoring law the model lacks
    (a bifilar suspension's is not m·g·S·sin θ) makes the frequency depend
    on the amplitude, and ω_n, the small-swing limit that J is computed from,
    then lies beyond both halves, not between them; a model that holds
    gives the same ω_n in both and the term vanishes. The first half is
    asked again without its first half-swing (``free_of_release``): u is
    the larger of the two, and the check records that half's ω_n.

    Kept on the fit (``fit.extra``): the identification asks it of the same final fit twice (whether
    an effect holds across the record, then the model-form uncertainty), and each asking fits two halves.
    """
    kept = fit.extra.get("segments")
    if kept is not None and kept[0] == sigma:
        return kept[1]
    check = _check_segments(fit, sigma)
    fit.extra["segments"] = (sigma, check)
    return check


def free_of_release(fit: ModelFit, first: slice) -> slice | None:
    """The first half of the record without its first half-swing, or None when the rest is too short to fit alone.

    A record's first samples are where the release is: a hand or a latch
    still touching the pendulum, a sensor settling, none of it a free swing.
    The half-swing ends at the first turning point of the fitted swing a
    quarter period or more after the first sample (a record that begins at a
    turning point, as a release from rest does, otherwise ends it at once).
    """
    t, v = fit.t[first], fit.extra["omega"][first]
    turns = np.flatnonzero(np.signbit(v[1:]) != np.signbit(v[:-1])) + 1
    turns = turns[t[turns] >= t[0] + 0.5 * math.pi / fit.value("omega_n")]
    if not turns.size:
        return None
    part = slice(first.start + int(turns[0]), first.stop)
    if _swings_in(fit.extra["theta"][part]) < MIN_SEGMENT_SWINGS or part.stop - part.start < 30:
        return None
    return part


def _u_form(fit: ModelFit, parts: Sequence[slice], ws: Sequence[float], ss: Sequence[float]) -> float:
    """The model-form u (rad/s) from two parts' ω_n and σ: the larger of their scatter about the whole
    record's value and the whole's distance to ω_n extrapolated to zero amplitude through them."""
    w, s = fit.value("omega_n"), fit.stdev("omega_n")
    # a half's estimate differs from the whole's by its own information's share: variance σ_h² − σ²
    excess = [(wi - w) ** 2 - max(si**2 - s**2, 0.0) for wi, si in zip(ws, ss)]
    u_scatter = math.sqrt(max(float(np.mean(excess)), 0.0))
    # ω(m) = a + b·m through the halves, m the mean square true angle of each: a at m = 0
    theta = fit.extra["theta"]
    m1, m2 = (float(np.mean(theta[part] ** 2)) for part in parts)
    u_amp = 0.0
    if m1 > m2 > 0:
        # leverage of the extrapolation, bounded where the amplitude barely changes between the
        # halves (then their difference is not the amplitude's doing and the scatter term holds it)
        lev = min(m2 / (m1 - m2), MAX_LEVERAGE)
        a = ws[1] + lev * (ws[1] - ws[0])
        var_a = ((1 + lev) * ss[1]) ** 2 + (lev * ss[0]) ** 2
        u_amp = math.sqrt(max((a - w) ** 2 - max(var_a - s**2, 0.0), 0.0))
    return max(u_scatter, u_amp)


def _check_segments(fit: ModelFit, sigma: float) -> SegmentCheck | None:
    fitted = segment_fits(fit, sigma)
    parts = halves(fit)
    if fitted is None or parts is None:
        return None
    t_split, segs = fitted
    ws = [f.value("omega_n") for f in segs]
    ss = [f.stdev("omega_n") for f in segs]
    sd = math.hypot(ss[0], ss[1])
    z = abs(ws[0] - ws[1]) / sd if sd > 0 else math.inf
    p = float(erfc(z / math.sqrt(2.0)))
    u = _u_form(fit, parts, ws, ss)
    # a transient of the release in the first half can move its ω_n onto the second's and hide a
    # model that does not hold: the first half is asked again without it, and the larger u is kept
    free, first_free = free_of_release(fit, parts[0]), None
    if free is not None:
        try:
            g = refit_segment(fit, free, sigma)
        except IdentificationError:
            g = None
        if g is not None:
            first_free = (float(fit.t[free.start]), g.value("omega_n"), g.stdev("omega_n"))
            u = max(u, _u_form(fit, (free, parts[1]), (first_free[1], ws[1]), (first_free[2], ss[1])))
    return SegmentCheck(t_split, tuple(ws), tuple(ss), z, p, u, *(first_free or (None, None, None)))


def effect_holds(fit: ModelFit, effect: str, sigma: float) -> tuple[bool, str, int]:
    """Whether a sensor-scale ``effect`` in ``fit`` holds across the record; returns (holds, why, simulations).

    A sensor's scale (gain, view) is a constant of the sensor: fitted in each
    half of the record its parameters must agree (χ² of their difference). A
    scale that changes with the swing's amplitude stands in for a restoring
    law the model lacks (a bifilar suspension's is not m·g·S·sin θ), and
    would buy a wrong ω_n. A record too short to split holds (nothing
    contradicts it).
    """
    fitted = segment_fits(fit, sigma)
    if fitted is None:
        return True, "the record is too short (or too poor) to fit its halves alone", 0
    _, (a, b) = fitted
    model = fit.model
    eff = next(e for e in model.effects if e.name == effect)
    sl = model.layout[effect]
    d = a.x[sl] - b.x[sl]
    cov = a.cov[sl, sl] + b.cov[sl, sl]
    try:
        chi2 = float(d @ np.linalg.solve(cov, d))
    except np.linalg.LinAlgError:
        chi2 = float(d @ np.linalg.pinv(cov) @ d)
    p = float(gammaincc(d.size / 2.0, chi2 / 2.0))
    words = ", ".join(f"{effect}.{q.name} {va:.4g} / {vb:.4g}" for q, va, vb in zip(eff.parameters, a.x[sl], b.x[sl]))
    return p >= EFFECT_P, (f"a sensor's scale is constant, but the first / second half give {words} "
                           f"(χ² {chi2:.1f} on {d.size}, p = {p:.2g})"), a.nfev + b.nfev


def bic_weights(bics: np.ndarray) -> np.ndarray:
    """Each model's BIC weight, exp(−ΔBIC/2) normalised over the models (ΔBIC from the least)."""
    w = np.exp(-(bics - bics.min()) / 2.0)
    return w / w.sum()


def competitors(steps: Sequence[Any], margin: float) -> tuple[tuple[Competitor, ...], float]:
    """Models within ``margin`` of BIC of the one each discovery round kept, and ω_n's spread over them (rad/s).

    steps: the loop's ``DiscoveryStep``s, whose candidate tables carry each
    fitted candidate's ω_n and the model's before the round. In a round that
    added an effect, the others fitted within the margin are rival
    explanations of the same residual; in the round that stopped, a
    candidate that lowered BIC, but not by the margin, is an explanation the
    data neither demand nor exclude. The spread is Σ w·(ω − ω_kept)² over
    each round's BIC weights, rounds added up.
    """
    out: list[Competitor] = []
    var = 0.0
    for st in steps:
        table = st.candidates
        fitted = {k: v for k, v in table.items() if "omega_n" in v and not v.get("screened") and not v.get("rejected")}
        if st.chosen is not None:
            if st.chosen not in fitted:
                continue
            ref_bic, ref_w = fitted[st.chosen]["bic"], fitted[st.chosen]["omega_n"]
            rivals = {k: v for k, v in fitted.items() if k != st.chosen and v["bic"] - ref_bic < margin}
        else:
            if st.omega_n_before is None:
                continue
            ref_bic, ref_w = st.bic_before, st.omega_n_before
            rivals = {k: v for k, v in fitted.items() if v["bic"] - ref_bic < margin}
        if not rivals:
            continue
        w = bic_weights(np.array([ref_bic] + [v["bic"] for v in rivals.values()]))
        for (name, v), wi in zip(rivals.items(), w[1:]):
            delta = v["omega_n"] - ref_w
            var += float(wi) * delta**2
            change = f"{name} instead of {st.chosen}" if st.chosen is not None else f"{name} added"
            out.append(Competitor(change, v["bic"] - ref_bic, float(wi), v["omega_n"], delta))
    return tuple(out), math.sqrt(var)
