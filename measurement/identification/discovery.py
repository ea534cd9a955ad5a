"""Step 3, discovery: each round, every candidate effect is scored against the current fit.

The score is a Lagrange-multiplier test: the first-order likelihood gain of
adding the effect, whitened by the noise model. Those that could lower BIC
are fitted (side by side, ``threads.parallel_map``), and the one with the
lowest BIC is added if it lowers BIC by more than the margin and, for a
sensor's scale that moves ω_n, holds across the record. BIC is the likelihood
under the AR noise model, so the power grows with the record and coloured
noise is not "explained" by an effect; no ratio to the noise floor stops the loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from ..consistency import effect_holds
from ..diagnostics import diagnose
from ..effect_base import Effect
from ..effects import EFFECTS, candidate_effects, resolve_effects, with_effect
from ..errors import IdentificationError
from ..fit import ModelFit, fit_model, swing_amplitude
from ..model import Model
from ..noise import fit_noise
from ..residual import Diagnostics
from ..restoring import restoring as restoring_law
from ..result import DiscoveryStep
from ..rig import Rig
from ..trace import READING_UNITS
from .options import Options
from .preparation import Prepared
from .threads import parallel_map

#: residual RMS over the noise floor up to which a candidate's first-order score is trusted to skip its fit
SCREEN_TRUST = 4.0


@dataclass(frozen=True)
class Score:
    """First-order (linearised) value of adding an effect to a fit.

    d_bic: the BIC change the linearised refit predicts, the noise model
    refitted to the predicted residual as the full fit would; step: the
    first-order parameter values of the effect.
    """

    d_bic: float
    residual_rms: float
    step: np.ndarray


def score_effect(current: ModelFit, effect: Effect, q: np.ndarray | None = None) -> Score:
    """Score ``effect`` against ``current`` without fitting it (one simulation per dynamic parameter).

    The effect's columns g = ∂y_model/∂p at p = 0 join the current Jacobian
    in one linearised least-squares step (a Gauss–Newton step from the
    current fit: the Lagrange-multiplier test in its likelihood-ratio form);
    the predicted residual gets its own noise model, exactly as a fit would,
    so that an AR model cannot hide a deterministic term the effect explains.
    A parameter bounded below at 0 (a dissipation) that would have to go
    negative gains nothing. q: the orthonormal basis of the current scaled
    Jacobian (``current_basis``), the same for every candidate of a round.
    """
    model = current.model
    rig = model.rig
    cand = Model(rig, tuple(resolve_effects(with_effect(model.effect_names, effect), rig)))
    values = {e.name: current.effect(e.name) for e in model.effects}
    if effect.refines is not None:
        # at its other parameters' zero the effect is the one it refines, with the same values
        values[effect.name] = current.effect(effect.refines) + [0.0] * (len(effect.parameters) - 1)
    x = cand.vector((current.value("theta0"), current.value("omega0"), current.value("omega_n")),
                    values, current.value("offset"))
    t = current.t
    ts = t - t[0]
    # with the effect at 0 the candidate's swing is the current fit's (kept on the fit: no simulation)
    theta, omega = current.extra["theta"], current.extra["omega"]
    base = current.fitted
    sl = cand.layout[effect.name]
    if effect.role == "sensor":
        G = effect.sensor_basis(ts, model.reading(theta, omega))
    else:
        # a step whose torque is 1e-6 of the restoring one: linear, and far above round-off
        w = current.value("omega_n")
        restoring = restoring_law(rig.kind, theta, rig.geometry)
        col = np.sqrt(np.mean(effect.basis(theta, omega) ** 2, axis=0))
        h = 1e-6 * w**2 * float(np.sqrt(np.mean(restoring**2))) / np.where(col > 0, col, 1.0)
        # a parameter the effect is not linear in is screened by a secant of its typical size
        amplitude = float(np.max(np.abs(theta)))
        h = np.array([hj if size is None else size for hj, size in zip(h, effect.parameter_scales(amplitude))])
        G = np.empty((t.size, sl.stop - sl.start))
        for j in range(G.shape[1]):
            xp = x.copy()
            xp[sl.start + j] += h[j]
            G[:, j] = (cand.measured(xp, ts, *cand.true_angle(xp, t, current.max_step)) - base) / h[j]
    r = current.effective
    if q is None:
        q = current_basis(current)
    Gp = G - q @ (q.T @ G)
    rp = r - q @ (q.T @ r)
    step, *_ = np.linalg.lstsq(Gp, -rp, rcond=None)
    lower = np.array([p.lower for p in effect.parameters])
    step = np.where((lower >= 0) & (step < 0), 0.0, step)
    predicted = rp + Gp @ step
    noise = fit_noise(predicted)
    n = current.n
    bic = n * math.log(max(noise.innovation_var, 1e-300)) + (current.k + len(step) + noise.order) * math.log(n)
    return Score(bic - current.bic, float(np.sqrt(np.mean(predicted**2))), step)


def current_basis(current: ModelFit) -> np.ndarray:
    """Orthonormal basis (QR) of the scaled Jacobian of ``current``: what a candidate's columns are projected off."""
    q, _ = np.linalg.qr(current.jac * current.scales)
    return q


class Move(NamedTuple):
    """An effect the loop added, and what it did to ω_n.

    omega_n_change: ω_n after it minus before (rad/s); omega_n_std: the 1σ of ω_n after it (rad/s);
    start: the fit it was added to (the model without it, on the same samples).
    """

    effect: str
    omega_n_change: float
    omega_n_std: float
    start: ModelFit

    @property
    def moved(self) -> bool:
        """It moved ω_n by more than its σ."""
        return abs(self.omega_n_change) > self.omega_n_std


@dataclass(frozen=True)
class Discovery:
    """What the loop did: the final fit, each round's evidence, the effects it added, and the
    simulations it spent."""

    final: ModelFit
    steps: list[DiscoveryStep]
    moves: list[Move]
    spent: int


@dataclass
class _Round:
    """One round's candidates: those fitted (name → fit), the table of every one scored, and the
    simulations spent."""

    tried: dict[str, ModelFit]
    table: dict[str, dict[str, float]]
    spent: int = 0


def _fit_candidates(current: ModelFit, cands: list[Effect], prep: Prepared, rig: Rig,
                    f_scale: float | None) -> _Round:
    """Every candidate scored against ``current``, and fitted unless its score shows it cannot pay."""
    floor = current.n * prep.noise**2
    excess = max(current.rss - floor, 0.01 * current.rss)
    q = current_basis(current) if cands else None
    # Far above the noise the current fit may be in another basin than the true swing (a
    # cycle slipped over a long record, a wrong damping law at large amplitude): its
    # linearisation says nothing about a candidate then, so every candidate is fitted.
    screen = current.residual_rms <= SCREEN_TRUST * prep.noise

    def trial(cand: Effect) -> tuple[Score, ModelFit | None]:
        score = score_effect(current, cand, q)
        if screen and score.d_bic >= 0.0:
            return score, None
        model = Model(rig, tuple(resolve_effects(with_effect(current.model.effect_names, cand), rig)))
        try:
            return score, fit_model(model, current.t, current.y, prep.noise, previous=current, f_scale=f_scale)
        except IdentificationError:
            return score, None

    out = _Round({}, {})
    # the candidates are independent: fitted side by side, read back in library order
    for cand, (score, f) in zip(cands, parallel_map(trial, cands)):
        out.spent += len(cand.parameters)
        if f is None and score.d_bic >= 0.0:
            # the first-order gain cannot pay for the parameter: not worth a fit
            out.table[cand.name] = {"bic": current.bic + score.d_bic, "screened": 1.0,
                                    "residual_rms": score.residual_rms,
                                    "excess_explained": (current.rss - current.n * score.residual_rms**2) / excess}
            continue
        if f is None:
            continue
        out.spent += f.nfev
        out.tried[cand.name] = f
        out.table[cand.name] = {"bic": f.bic, "residual_rms": f.residual_rms,
                                "excess_explained": (current.rss - f.rss) / excess, "omega_n": f.value("omega_n")}
    return out


def _best_that_holds(rnd: _Round, current: ModelFit, prep: Prepared, options: Options) -> tuple[str | None, list[str]]:
    """The candidate of least BIC beyond the margin that also holds across the record (None: none), and
    in words those that did not.

    A sensor scale that moves ω_n by more than its σ must be the same in both halves of the record,
    or it stands in for a restoring law the model lacks, and would buy a wrong J.
    """
    tried, w_before = rnd.tried, current.value("omega_n")
    not_held: list[str] = []
    for name in sorted(tried, key=lambda k: tried[k].bic):
        f = tried[name]
        if f.bic - current.bic >= -options.bic_margin:
            break
        if EFFECTS[name].scale_parameters and abs(f.value("omega_n") - w_before) > f.stdev("omega_n"):
            holds, words, nfev = effect_holds(f, name, prep.noise)
            rnd.spent += nfev
            if not holds:
                rnd.table[name]["rejected"] = 1.0
                not_held.append(f"{name} does not hold across the record ({words})")
                continue
        return name, not_held
    return None, not_held


def _nothing_tried(number: int, current: ModelFit, table: dict[str, dict[str, float]]) -> DiscoveryStep:
    """The last round's record when no candidate was worth a fit."""
    reason = "no candidate effect left to try"
    if table:
        best_screen = min(table, key=lambda k: table[k]["bic"])
        reason = (f"no candidate could lower BIC (best first-order change: {best_screen} "
                  f"{table[best_screen]['bic'] - current.bic:+.1f})")
    return DiscoveryStep(number, current.residual_rms, current.bic, table, None, None, None, "", reason,
                         current.value("omega_n"))


def _nothing_added(number: int, current: ModelFit, rnd: _Round, not_held: list[str], rig: Rig, options: Options,
                   diagnosis: Callable[[ModelFit], Diagnostics]) -> DiscoveryStep:
    """The last round's record when no fitted candidate lowered BIC enough and held."""
    tried = rnd.tried
    best = min(tried, key=lambda k: tried[k].bic)
    d_bic = tried[best].bic - current.bic
    evidence = EFFECTS[best](rig).evidence(diagnosis(current))
    reason = "; ".join(not_held) if not_held else (
        f"best candidate {best} changes BIC by only {d_bic:+.1f} (needs < {-options.bic_margin:g})")
    return DiscoveryStep(number, current.residual_rms, current.bic, rnd.table, None, None, None, evidence,
                         reason, current.value("omega_n"))


def _added(number: int, current: ModelFit, best: str, rnd: _Round, not_held: list[str], rig: Rig,
           diagnosis: Callable[[ModelFit], Diagnostics]) -> DiscoveryStep:
    """The round's record when ``best`` was added."""
    bf = rnd.tried[best]
    d_bic = bf.bic - current.bic
    evidence = EFFECTS[best](rig).evidence(diagnosis(current))
    reason = (f"BIC {d_bic:+.1f} (noise model AR({bf.noise.order})), residual RMS "
              f"{current.residual_rms:.3g} → {bf.residual_rms:.3g} {READING_UNITS[rig.measures]}")
    if not_held:
        reason += "; " + "; ".join(not_held)
    return DiscoveryStep(number, current.residual_rms, current.bic, rnd.table, best, bf.residual_rms, bf.bic,
                         evidence, reason, current.value("omega_n"))


def discover(fit: ModelFit, prep: Prepared, rig: Rig, options: Options, f_scale: float | None = None,
             diagnosis: Callable[[ModelFit], Diagnostics] | None = None) -> Discovery:
    """The discovery loop from ``fit``: the final fit, its steps, each effect added (``Move``) and the
    simulations spent.

    diagnosis: ``diagnose`` of a fit with the record's noise floor (the
    caller's, to diagnose the final fit only once).
    """
    if diagnosis is None:
        def diagnosis(f: ModelFit) -> Diagnostics:
            return diagnose(f, prep.noise, prep.stuck)
    current = fit
    steps: list[DiscoveryStep] = []
    moves: list[Move] = []
    spent = 0
    allowed = set(options.candidates) if options.candidates is not None else set(EFFECTS)
    amplitude = swing_amplitude(fit)
    for number in range(1, options.max_rounds + 1):
        cands = [c for c in candidate_effects(rig, current.model.effect_names)
                 if c.name in allowed and c.identifiable(amplitude)]
        rnd = _fit_candidates(current, cands, prep, rig, f_scale)
        if not rnd.tried:
            spent += rnd.spent
            steps.append(_nothing_tried(number, current, rnd.table))
            break
        best, not_held = _best_that_holds(rnd, current, prep, options)
        spent += rnd.spent
        if best is None:
            steps.append(_nothing_added(number, current, rnd, not_held, rig, options, diagnosis))
            break
        steps.append(_added(number, current, best, rnd, not_held, rig, diagnosis))
        bf = rnd.tried[best]
        moves.append(Move(best, bf.value("omega_n") - current.value("omega_n"), bf.stdev("omega_n"), current))
        current = bf
    return Discovery(current, steps, moves, spent)
