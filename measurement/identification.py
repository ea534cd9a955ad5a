"""Identification of a recorded swing, with residual-driven model discovery.

    prepare  → angle unwrapped, noise floor, glitches removed, swing window
               (release … stop, or a long gap after which the swing does
               not clearly continue)
    baseline → the declared model fitted to the whole record; a robust
               (soft-L1) loss from then on when wild samples are left
    discover → each round, every candidate effect is scored against the
               current fit (a Lagrange-multiplier test: the first-order
               likelihood gain of adding it, whitened by the noise model);
               those that could lower BIC are fitted, and the one with the
               lowest BIC is added if it lowers BIC by more than the margin.
               BIC is the likelihood under the AR noise model, so the power
               grows with the record and coloured noise is not "explained"
               by an effect; no ratio to the noise floor stops the loop.
    hold     → an effect that moved ω_n by more than its σ is withdrawn when the
               model it ends in gives another ω_n in each half of the record
               (``hold_across``); its ω_n stays a rival in the uncertainty
    guard    → a final model that fits worse than a model it contains (the declared
               one, an earlier step) on the same samples left the optimum: refitted
               from that model's values, or that model kept (``keep_nested_order``);
               a fit whose residual is comparable to the swing carries
               ``fit_not_converged`` (``follows_swing``)
    report   → before/after, the evidence of every step, and
               ``unmodeled_residual`` when structure is left that no library
               effect explains (never forced into a wrong effect).
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Callable, Sequence

import numpy as np
from threadpoolctl import ThreadpoolController

from . import flags as F
from .consistency import Competitor, ModelForm, SegmentCheck, bic_weights, check_segments, competitors, effect_holds
from .diagnostics import Diagnostics, diagnose
from .effects import EFFECTS, Effect, candidate_effects, resolve_effects, with_effect
from .errors import IdentificationError, RigError, TraceError, UnknownEffectError
from .fit import ModelFit, fit_model, initial_guess
from .noise import fit_noise
from .model import Model
from .result import DiscoveryStep, IdentificationResult, ModelSummary, Quantity
from .rig import Rig
from .signal import (MAX_GRID_PER_SAMPLE, Swings, deviation_table, find_swings, noise_floor, robust_std,
                     spike_candidates, swing_window)
from .trace import Trace
from .uncertainty import Budget, PendulumInputs


@dataclass(frozen=True)
class Options:
    """Identification settings.

    discover: run the discovery loop (False: fit the declared model only).
    candidates: effects the loop may add (None: every library effect that
    exists on the rig).
    min_swings: fewer full swings in the record is an input error.
    bic_margin: an added effect must lower BIC (under the noise model) by
    more than this: e^(−margin/2) is the Bayes factor it must beat.
    outlier_sigma: residuals beyond this many robust σ are glitches.
    robust_scale: the soft-L1 loss's scale in robust σ of the declared
    model's residual (used only when wild samples are left after the screen).
    gap_periods: a gap of more than this many swing periods without samples
    ends the window, unless the swing clearly continues after it.
    """

    discover: bool = True
    candidates: tuple[str, ...] | None = None
    min_swings: float = 3.0
    bic_margin: float = 10.0
    outlier_sigma: float = 6.0
    robust_scale: float = 3.0
    gap_periods: float = 1.5
    max_rounds: int = 5


@dataclass(frozen=True, eq=False)
class Prepared:
    """The samples that are fitted and what was learnt preparing them."""

    t: np.ndarray
    y: np.ndarray
    noise: float
    start: int
    stop: int
    release_detected: bool
    stopped: bool  # the window was cut before the end of the record
    stuck: bool    # ... because the pendulum came to rest
    outliers: np.ndarray  # indices into the original trace
    n_unwrapped: int = 0  # 2π jumps removed from the angle
    gap_cut_at: float | None = None  # s: the window ends at a long gap starting here
    swings: Swings | None = None  # of (t, y) about their median, hysteresis 3·noise
    noise_robust: float = 0.0  # the noise floor from the median absolute deviation (immune to wild samples), rad


def unwrap_angle(y: np.ndarray) -> tuple[np.ndarray, int]:
    """Remove 2π jumps (an angle read in (−π, π] as the swing passes ±π); returns (angle, jumps)."""
    jumps = int(np.sum(np.abs(np.diff(y)) > 1.5 * math.pi))
    if not jumps:
        return y, 0
    return np.unwrap(y, discont=1.5 * math.pi), jumps


def _gap_cut(t: np.ndarray, y: np.ndarray, noise: float, periods: float, sw: Swings) -> int | None:
    """Index after which a gap of more than ``periods`` swing periods ends the window (None: no such gap).

    A gap is kept inside the window only when the swing clearly continues
    after it: at least two full swings well above the noise (10σ). A tracker
    that loses the pendulum often writes a burst of wild samples before it
    stops: steps between samples far beyond the swing's own (4 × their 99th
    percentile) within the last period before the gap end the window too.
    sw: ``find_swings(t, y, hysteresis=3 * noise)``.
    """
    wd = sw.damped_frequency
    if not (math.isfinite(wd) and wd > 0):
        return None
    period = 2 * math.pi / wd
    long = np.flatnonzero(np.diff(t) > periods * period)
    # a gap is bridged only while the span stays within the samples' own grid: the simulation steps
    # through a gap, so a long one would cost time by the span, not by the samples
    bridgeable = float(t[-1] - t[0]) <= MAX_GRID_PER_SAMPLE * t.size * float(np.median(np.diff(t)))
    for g in long:
        after_t, after_y = t[g + 1:], y[g + 1:]
        if bridgeable and after_t.size >= 10:
            sa = find_swings(after_t, after_y, centre=sw.centre, hysteresis=10 * noise)
            if sa.count >= 2:
                continue
        steps = np.abs(np.diff(y[:g + 1]))
        lo = int(np.searchsorted(t, t[g] - period))
        if lo > 10:
            wild = np.flatnonzero(steps[lo:] > max(4 * float(np.quantile(steps[:lo], 0.99)), 10 * noise))
            if wild.size:
                return lo + int(wild[0])
        return int(g)
    return None


def prepare(trace: Trace, options: Options = Options()) -> Prepared:
    """Unwrapping, noise floor, swing window and glitch removal; raises TraceError when too little swings."""
    t_all = trace.t
    y_all, n_unwrapped = unwrap_angle(trace.angle)
    if len(trace) < 30:
        raise TraceError(f"{trace.source}: only {len(trace)} samples; expected at least 30 covering {options.min_swings:g} swings")
    span = float(np.ptp(y_all))
    if span == 0:
        raise TraceError(f"{trace.source}: the angle never changes; expected a free swing")
    floor = 1e-9 * span  # noise-free simulations still need a scale
    table = deviation_table(y_all, t_all)  # the neighbour predictions both floors and the glitch screen read
    noise_robust = max(noise_floor(y_all, robust=True, t=t_all, table=table), floor)
    spikes = spike_candidates(y_all, noise_robust, t=t_all, table=table)
    noise = max(noise_floor(y_all, exclude=spikes, t=t_all, table=table), floor)
    keep = np.ones(y_all.size, dtype=bool)
    keep[spikes] = False
    win = swing_window(t_all[keep], y_all[keep], noise)
    idx = np.flatnonzero(keep)[win.start:win.stop]
    gap_cut_at = None
    t, y = t_all[idx], y_all[idx]
    sw = find_swings(t, y, hysteresis=3 * noise)
    cut = _gap_cut(t, y, noise, options.gap_periods, sw)
    if cut is not None and cut + 1 >= 30:
        gap_cut_at = float(t_all[idx[cut]])
        idx = idx[:cut + 1]
        t, y = t_all[idx], y_all[idx]
        sw = find_swings(t, y, hysteresis=3 * noise)
    if sw.count < options.min_swings:
        raise TraceError(
            f"{trace.source}: only {sw.count:g} full swing(s) found; expected at least {options.min_swings:g} "
            "(record longer, or release from a larger angle)"
        )
    per_period = 2 * math.pi / sw.damped_frequency / float(np.median(np.diff(t)))
    if per_period < 6:
        raise TraceError(
            f"{trace.source}: {per_period:.1f} samples per swing period; expected at least 6 (sample faster)"
        )
    return Prepared(t=t, y=y, noise=noise, start=int(idx[0]), stop=int(idx[-1]) + 1,
                    release_detected=win.release_detected, stopped=win.stop_detected or gap_cut_at is not None,
                    stuck=win.stuck, outliers=np.asarray(spikes, dtype=int), n_unwrapped=n_unwrapped,
                    gap_cut_at=gap_cut_at, swings=sw, noise_robust=noise_robust)


def _propagate(fn: Callable[[np.ndarray], float], x: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
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


def _inertia(rig: Rig, omega_n: float) -> float | None:
    c = rig.restoring_constant
    return None if c is None else c / omega_n**2


def _defined(value: float | None) -> float:
    """value as a float, NaN where it is undefined (None)."""
    return math.nan if value is None else float(value)


def _effect_quantities(fit: ModelFit, rig: Rig, role: Sequence[str]) -> dict[str, dict[str, Quantity]]:
    """Effect → its fitted (normalised) and physical values with uncertainties, for effects of ``role``."""
    model, x, cov = fit.model, fit.x, fit.cov
    out: dict[str, dict[str, Quantity]] = {}
    for e in model.effects:
        if e.role not in role:
            continue
        sl = model.layout[e.name]
        params: dict[str, Quantity] = {}
        for p, v, s in zip(e.parameters, x[sl], fit.std[sl]):
            params[p.name] = Quantity(float(v), float(s), p.unit)

        def physical(xx: np.ndarray, _e: Effect = e) -> dict[str, float | None]:
            w = model.value(xx, "omega_n")
            return _e.physical(model.values(xx, _e.name), _inertia(rig, w), w)

        for name, val in physical(x).items():
            if val is None:
                params[name] = Quantity(None, None, e.unit_of(name))
            else:
                # a quantity undefined beside x (Dahl's spring as θ_c crosses 0) has no uncertainty
                v, s = _propagate(lambda xx, _n=name: _defined(physical(xx)[_n]), x, cov)
                params[name] = Quantity(v, s, e.unit_of(name))
        out[e.name] = params
    return out


def _summary(fit: ModelFit, rig: Rig) -> ModelSummary:
    w, ws = fit.value("omega_n"), fit.stdev("omega_n")
    J = _inertia(rig, w)
    return ModelSummary(
        effects=fit.model.effect_names, J=J, J_std=None if J is None else 2 * J * ws / w,
        omega_n=w, omega_n_std=ws, residual_rms=fit.residual_rms, bic=fit.bic, aic=fit.aic,
        damping=_effect_quantities(fit, rig, ("damping",)),
    )


def _omega_n_at_nominal_scale(fit: ModelFit) -> tuple[list[str], float] | None:
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


def _omega_n_std_view(fit: ModelFit, view: dict) -> float:
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


def _omega_n_per_scale(fit: ModelFit) -> float:
    """∂ω_n/∂s (rad/s per unit relative scale): how ω_n follows an angle read (1 + s) times too large.

    The fit's linear response (the least-squares pseudo-inverse of its Jacobian) to the error s·y it
    would see; zero for a linear restoring law, where the amplitude does not enter ω_n.
    """
    error = (fit.fitted - fit.value("offset"))[:, None]
    response = np.linalg.lstsq(fit.jac * fit.scales, error, rcond=None)[0] * fit.scales[:, None]
    return float(response[fit.model.index("omega_n"), 0])


def budgets(rig: Rig, omega_n: float, omega_n_std: float, *, dof: float = math.inf, model: float = 0.0,
            view: float | None = None, scale_response: float | None = None) -> dict[str, Budget]:
    """The uncertainty budgets (measurand → ``Budget``) of a swing identified at ω_n ± σ on ``rig``.

    model, view: the model-form and camera-view 1σ of ω_n (rad/s); scale_response: ∂ω_n/∂s of the
    fit, for a sensor declared calibrated (its ``angle_scale_std`` then enters).
    """
    obj = rig.object
    return PendulumInputs(
        omega_n=omega_n, omega_n_std=omega_n_std, omega_n_dof=dof, omega_n_model=model, omega_n_view=view,
        clock_ppm=rig.clock_accuracy_ppm,
        angle_scale=None if scale_response is None else (scale_response, rig.angle_scale_std),
        rig_kind=rig.kind, stiffness=rig.stiffness, stiffness_std=rig.stiffness_std,
        mass=rig.mass, mass_std=rig.mass_std, com_distance=rig.com_distance, com_distance_std=rig.com_distance_std,
        g=rig.g, g_std=rig.g_std, tare=rig.tare_inertia, tare_std=rig.tare_inertia_std,
        cov_k_tare=rig.stiffness_tare_covariance,
        object_mass=None if obj is None else obj.mass, object_mass_std=None if obj is None else obj.mass_std,
        axis_offset=None if obj is None else obj.axis_offset, axis_offset_std=None if obj is None else obj.axis_offset_std,
    ).budgets()


#: identification passes on a record with wild samples: each sets aside those its model shows
CLEANING_PASSES = 3


def _departures(residual: np.ndarray, floor: float) -> tuple[np.ndarray, float]:
    """Each residual's distance from their median in robust σ, and that σ floored by ``floor`` (rad).

    outlier_sigma is read on this scale: the floor keeps a residual quieter than the noise (an
    encoder's steps) from making every sample an outlier.
    """
    scale = max(robust_std(residual), floor)
    return np.abs(residual - np.median(residual)) / scale, scale


def _without_wild(fit: ModelFit, prep: Prepared, trace: Trace, options: Options) -> Prepared | None:
    """``prep`` without the isolated samples beyond outlier_sigma robust σ of ``fit``'s residual, or None if none is.

    The scale is floored by the robust noise floor, not the noise floor: that is itself raised by the very
    samples to be found.
    """
    r, _ = _departures(fit.residual, prep.noise_robust)
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


def _remove_outliers(fit: ModelFit, prep: Prepared, options: Options) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    bad = _departures(fit.residual, prep.noise)[0] > options.outlier_sigma
    return fit.t[~bad], fit.y[~bad], np.flatnonzero(bad)


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
        G = effect.sensor_basis(ts, theta)
    else:
        # a step whose torque is 1e-6 of the restoring one: linear, and far above round-off
        w = current.value("omega_n")
        restoring = np.sin(theta) if rig.kind == "compound" else theta
        col = np.sqrt(np.mean(effect.basis(theta, omega) ** 2, axis=0))
        h = 1e-6 * w**2 * float(np.sqrt(np.mean(restoring**2))) / np.where(col > 0, col, 1.0)
        # a parameter the effect is not linear in is screened by a secant of its typical size
        amplitude = float(np.max(np.abs(theta)))
        h = np.array([hj if size is None else size for hj, size in zip(h, effect.parameter_scales(amplitude))])
        G = np.empty((t.size, sl.stop - sl.start))
        for j in range(G.shape[1]):
            xp = x.copy()
            xp[sl.start + j] += h[j]
            G[:, j] = (cand.measured(xp, ts, cand.true_angle(xp, t, current.max_step)[0]) - base) / h[j]
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


def usable_cores() -> int:
    """Cores this process may run on (a ``taskset`` or a container's CPU set counts)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def parallel_map(fn: Callable, items: Sequence) -> list:
    """[fn(item) for item in items], on threads when more than one core is usable.

    Threads, not processes: the integrator's compiled kernel and the BLAS
    calls release the GIL, and threads cost no start-up, no pickling and no
    second copy of numpy, scipy and the kernels in memory. On one core the
    items run one after the other in this thread.
    """
    workers = min(len(items), usable_cores())
    if workers <= 1:
        return [fn(item) for item in items]
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="moi-fit") as pool:
        return list(pool.map(fn, items))


def discover(fit: ModelFit, prep: Prepared, rig: Rig, options: Options,
             f_scale: float | None = None,
             diagnosis: Callable[[ModelFit], Diagnostics] | None = None
             ) -> tuple[ModelFit, list[DiscoveryStep], int, list[tuple[str, float, float, ModelFit]]]:
    """The discovery loop; returns the final fit, its steps, the simulations spent and each added
    effect with the change of ω_n it made, the σ of ω_n after it (rad/s) and the fit it was added to.

    diagnosis: ``diagnose`` of a fit with the record's noise floor (the
    caller's, to diagnose the final fit only once).
    """
    if diagnosis is None:
        def diagnosis(f: ModelFit) -> Diagnostics:
            return diagnose(f, prep.noise, prep.stuck)
    current = fit
    steps: list[DiscoveryStep] = []
    moves: list[tuple[str, float, float, ModelFit]] = []
    spent = 0
    allowed = set(options.candidates) if options.candidates is not None else set(EFFECTS)
    amplitude = float(np.max(np.abs(fit.fitted - fit.value("offset"))))
    for rnd in range(1, options.max_rounds + 1):
        tried: dict[str, ModelFit] = {}
        table: dict[str, dict[str, float]] = {}
        floor = current.n * prep.noise**2
        excess = max(current.rss - floor, 0.01 * current.rss)
        cands = [c for c in candidate_effects(rig, current.model.effect_names)
                 if c.name in allowed and c.identifiable(amplitude)]

        q = current_basis(current) if cands else None

        # Far above the noise the current fit may be in another basin than the true swing (a
        # cycle slipped over a long record, a wrong damping law at large amplitude): its
        # linearisation says nothing about a candidate then, so every candidate is fitted.
        screen = current.residual_rms <= SCREEN_TRUST * prep.noise

        def trial(cand: Effect, current: ModelFit = current, q: np.ndarray | None = q) -> tuple[Score, ModelFit | None]:
            score = score_effect(current, cand, q)
            if screen and score.d_bic >= 0.0:
                return score, None
            model = Model(rig, tuple(resolve_effects(with_effect(current.model.effect_names, cand), rig)))
            try:
                return score, fit_model(model, current.t, current.y, prep.noise, previous=current, f_scale=f_scale)
            except IdentificationError:
                return score, None

        # the candidates are independent: fitted side by side, read back in library order
        for cand, (score, f) in zip(cands, parallel_map(trial, cands)):
            spent += len(cand.parameters)
            if f is None and score.d_bic >= 0.0:
                # the first-order gain cannot pay for the parameter: not worth a fit
                table[cand.name] = {"bic": current.bic + score.d_bic, "screened": 1.0,
                                    "residual_rms": score.residual_rms,
                                    "excess_explained": (current.rss - current.n * score.residual_rms**2) / excess}
                continue
            if f is None:
                continue
            spent += f.nfev
            tried[cand.name] = f
            table[cand.name] = {"bic": f.bic, "residual_rms": f.residual_rms,
                                "excess_explained": (current.rss - f.rss) / excess, "omega_n": f.value("omega_n")}
        w_before = current.value("omega_n")
        if not tried:
            best_screen = min(table, key=lambda k: table[k]["bic"]) if table else None
            reason = "no candidate effect left to try" if not table else (
                f"no candidate could lower BIC (best first-order change: {best_screen} "
                f"{table[best_screen]['bic'] - current.bic:+.1f})")
            steps.append(DiscoveryStep(rnd, current.residual_rms, current.bic, table, None, None, None, "", reason,
                                       w_before))
            break
        # The best by BIC that also holds across the record: a sensor scale that moves ω_n by
        # more than its σ must be the same in both halves of the record, or it stands in for a
        # restoring law the model lacks, and would buy a wrong J.
        best = None
        not_held: list[str] = []
        for name in sorted(tried, key=lambda k: tried[k].bic):
            f = tried[name]
            if f.bic - current.bic >= -options.bic_margin:
                break
            if EFFECTS[name].scale_parameters and abs(f.value("omega_n") - w_before) > f.stdev("omega_n"):
                holds, words, nfev = effect_holds(f, name, prep.noise)
                spent += nfev
                if not holds:
                    table[name]["rejected"] = 1.0
                    not_held.append(f"{name} does not hold across the record ({words})")
                    continue
            best = name
            break
        if best is None:
            best = min(tried, key=lambda k: tried[k].bic)
            d_bic = tried[best].bic - current.bic
            evidence = EFFECTS[best](rig).evidence(diagnosis(current))
            reason = "; ".join(not_held) if not_held else (
                f"best candidate {best} changes BIC by only {d_bic:+.1f} (needs < {-options.bic_margin:g})")
            steps.append(DiscoveryStep(rnd, current.residual_rms, current.bic, table, None, None, None, evidence,
                                       reason, w_before))
            break
        bf = tried[best]
        d_bic = bf.bic - current.bic
        evidence = EFFECTS[best](rig).evidence(diagnosis(current))
        reason = (f"BIC {d_bic:+.1f} (noise model AR({bf.noise.order})), residual RMS "
                  f"{current.residual_rms:.3g} → {bf.residual_rms:.3g} rad")
        if not_held:
            reason += "; " + "; ".join(not_held)
        steps.append(DiscoveryStep(rnd, current.residual_rms, current.bic, table, best, bf.residual_rms, bf.bic,
                                   evidence, reason, w_before))
        moves.append((best, bf.value("omega_n") - w_before, bf.stdev("omega_n"), current))
        current = bf
    return current, steps, spent, moves


@dataclass(frozen=True)
class Withdrawn:
    """Effects taken back because the ω_n they moved does not hold across the record.

    effects: the effects withdrawn; omega_n: the model's with them (rad/s);
    d_bic: its BIC minus the kept model's; segments: its halves; model_effects: that model's effects.
    """

    effects: tuple[str, ...]
    omega_n: float
    omega_n_std: float
    d_bic: float
    segments: SegmentCheck
    model_effects: tuple[str, ...]

    def rival(self, kept_omega_n: float) -> Competitor:
        return Competitor(f"{', '.join(self.effects)} kept (the ω_n it moves does not hold across the record)",
                          self.d_bic, 1.0, self.omega_n, self.omega_n - kept_omega_n, self.model_effects)


def _fallback(names: Sequence[str], taken: Sequence[str],
              moves: Sequence[tuple[str, float, float, ModelFit]]) -> tuple[list[str], ModelFit | None]:
    """The effect names without ``taken``, each one's refined effect (Coulomb for Dahl) in its place, and
    the loop's last fit within them (the model itself, or a start that it contains; None: none)."""
    keep = [n for n in names if n not in taken]
    keep += [r for n in taken if (r := EFFECTS[n].refines) is not None and r not in keep]
    earlier = [f for *_, f in moves if set(f.model.effect_names) <= set(keep)]
    return keep, (earlier[-1] if earlier else None)


def hold_across(final: ModelFit, base: ModelFit, moves: Sequence[tuple[str, float, float, ModelFit]], prep: Prepared,
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
    Returns (fit, what was withdrawn or None, simulations spent).
    """
    names = final.model.effect_names
    movers = [n for n, d, sd, _ in moves if abs(d) > sd and n in names and not EFFECTS[n].scale_parameters]
    w = final.value("omega_n")
    if not movers or abs(w - base.value("omega_n")) <= final.stdev("omega_n"):
        return final, None, 0
    seg = check_segments(final, prep.noise)
    if seg is None or not seg.disagree:
        return final, None, 0
    keep, earlier = _fallback(names, movers, moves)
    model = Model(rig, tuple(resolve_effects(keep, rig)))
    previous = earlier or base
    nfev = 0
    if previous.model.effect_names != model.effect_names:
        try:
            previous = fit_model(model, final.t, final.y, prep.noise, previous=previous, f_scale=f_scale)
        except IdentificationError:
            return final, None, 0
        nfev = previous.nfev
    return previous, Withdrawn(tuple(movers), w, final.stdev("omega_n"), final.bic - previous.bic, seg,
                               final.model.effect_names), nfev


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
        return Competitor(f"{self.law} (a restoring law, not offered on this rig) instead of {self.effect}",
                          self.d_bic, self.weight, self.omega_n, self.omega_n - kept_omega_n, self.model_effects)


def law_rival(final: ModelFit, moves: Sequence[tuple[str, float, float, ModelFit]], prep: Prepared, rig: Rig,
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
    mimics = [law for n, d, sd, _ in moves if n in names and abs(d) > sd
              and (law := EFFECTS[n].unweighed_law(rig.kind)) is not None and law not in names]
    if not mimics:
        return None, 0
    law = mimics[-1]
    # every kept effect that stands for the same law gives way to it (a sensor's gain and view both)
    taken = [n for n in names if EFFECTS[n].mimics == law]
    keep, earlier = _fallback(names, taken, moves)
    model = Model(rig, tuple(resolve_effects(keep + [law], rig)))
    try:
        fit = fit_model(model, final.t, final.y, prep.noise, previous=earlier or final, f_scale=f_scale)
    except IdentificationError:
        return None, 0
    d_bic = fit.bic - final.bic
    weight = float(bic_weights(np.array([final.bic, fit.bic]))[1])
    return LawRival(", ".join(taken), law, fit.value("omega_n"), d_bic, weight, model.effect_names), fit.nfev


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
#: the worst of the real records, a bifilar suspension whose restoring law no effect matches, stands at 0.16
FOLLOW_LIMIT = 1.0 / 3.0


def _worse_than(fit: ModelFit, inner: ModelFit) -> bool:
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


def rival_frequencies(base: ModelFit, sigma: float, margin: float) -> tuple[ModelFit, tuple[Competitor, ...], float, int]:
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
        return base, (), 0.0, 0
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
        return kept, (), 0.0, spent
    bics = np.array([kept.bic] + [f.bic for f in rivals])
    weights = np.exp(-(bics - bics.min()) / 2.0)
    weights /= weights.sum()
    out = tuple(Competitor(f"the swing at {f.value('omega_n'):.4g} rad/s, which the sampling's gaps do not tell from "
                           f"{w_kept:.4g} (an alias)", f.bic - kept.bic, float(wi), f.value("omega_n"),
                           f.value("omega_n") - w_kept) for f, wi in zip(rivals, weights[1:]))
    return kept, out, math.sqrt(sum(c.weight * c.delta**2 for c in out)), spent


def follows_swing(fit: ModelFit, sigma: float) -> tuple[bool, float]:
    """(whether the fitted model follows the swing, its residual RMS over the fitted swing's RMS).

    It does not when the residual is far above the noise floor (``SCREEN_TRUST``) and comparable to
    the swing itself (``FOLLOW_LIMIT``): whatever J such a fit implies, it is not read from the swing.
    """
    swing = float(np.sqrt(np.mean((fit.fitted - fit.value("offset")) ** 2)))
    ratio = fit.residual_rms / swing if swing > 0 else math.inf
    return not (fit.residual_rms > SCREEN_TRUST * sigma and ratio > FOLLOW_LIMIT), ratio


def identify(trace: Trace, rig: Rig, options: Options = Options()) -> IdentificationResult:
    """Identify J, ω_n and the damping of ``trace`` on ``rig`` (see module doc)."""
    # The matrices here are tall and thin (samples × a few parameters): BLAS
    # threads only contend with each other and with the candidate fits'
    # threads, on a busy machine by a factor of 30 for an SVD.
    with _blas().limit(limits=1, user_api="blas"):
        return _identify(trace, rig, options)


@lru_cache(maxsize=1)
def _blas() -> ThreadpoolController:
    # finding the loaded BLAS libraries walks every shared object: once per process
    return ThreadpoolController()


def _identify(trace: Trace, rig: Rig, options: Options) -> IdentificationResult:
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
    prep = prepare(trace, options)
    declared = Model.from_names(rig, rig.declared)
    nfev = 0
    diagnosed: dict[int, tuple[ModelFit, Diagnostics]] = {}  # by id, the fit kept so its id is not reused

    def diagnosis(fit: ModelFit) -> Diagnostics:
        # the loop's last round may have diagnosed the final fit already (a fit is diagnosed with the
        # samples of its own pass: ``prep`` changes only between passes)
        if id(fit) not in diagnosed:
            diagnosed[id(fit)] = (fit, diagnose(fit, prep.noise, prep.stuck))
        return diagnosed[id(fit)][1]

    # Samples that the robust loss had to tame (wild or mis-dated ones) still weigh in every
    # model's BIC, where they drown an effect's evidence: once a pass has a model, those beyond
    # outlier_sigma of its residual are set aside and the loop runs again (CLEANING_PASSES at most).
    for last_pass in (k == CLEANING_PASSES - 1 for k in range(CLEANING_PASSES)):
        base = fit_model(declared, prep.t, prep.y, prep.noise, swings=prep.swings)
        nfev += base.nfev
        base, aliases, u_aliases, spent = rival_frequencies(base, prep.noise, options.bic_margin)
        nfev += spent
        # Wild samples the pre-screen left (bursts, a stalled tracker) must not
        # steer the fit or pass for an effect: with any beyond outlier_sigma robust
        # σ of the declared model's residual, every fit uses a soft-L1 loss whose
        # scale is set once here (one loss for all models keeps their BIC comparable).
        f_scale = None
        departures, scale = _departures(base.residual, prep.noise)
        if np.any(departures > options.outlier_sigma):
            f_scale = options.robust_scale * scale
            base = fit_model(declared, prep.t, prep.y, prep.noise, previous=base, f_scale=f_scale)
            nfev += base.nfev
        steps: list[DiscoveryStep] = []
        final = base
        withdrawn: Withdrawn | None = None
        moves: list[tuple[str, float, float, ModelFit]] = []
        if options.discover:
            final, steps, spent, moves = discover(base, prep, rig, options, f_scale, diagnosis)
            nfev += spent
            final, withdrawn, spent = hold_across(final, base, moves, prep, rig, f_scale)
            nfev += spent
        if last_pass or f_scale is None:
            break
        cleaner = _without_wild(final, prep, trace, options)
        if cleaner is None:
            break
        prep = cleaner
    # Glitches the pre-screen missed show in the final residual; judged there
    # because a structured baseline residual is not Gaussian. While the final
    # residual is itself structured, its peaks are not glitches: keep the data.
    diag: Diagnostics = diagnosis(final)
    bad = np.zeros(0, dtype=int)
    if not diag.structured and f_scale is None:
        t_fit, y_fit, bad = _remove_outliers(final, prep, options)
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
    # never a model worse than one it contains: the declared model's fit and each step's on the same samples
    slipped_from = final
    final, beaten_by, spent = keep_nested_order(final, [base] + [f for *_, f in moves], prep.noise)
    nfev += spent
    if beaten_by is not None:
        diag = diagnose(final, prep.noise, prep.stuck)
    follows, follow_ratio = follows_swing(final, prep.noise)

    w, ws = final.value("omega_n"), final.stdev("omega_n")
    # a sensor calibrated from the record itself carries its own uncertainty into ω_n, beside the fit's
    w_cal = _omega_n_std_view(final, view) if view is not None else None
    # the model's form: does it hold across the record, and do rival models the data cannot
    # tell apart give another ω_n (consistency.py)
    segments = check_segments(final, prep.noise)
    rivals, u_rivals = competitors(steps, options.bic_margin)
    if aliases:
        rivals += aliases
        u_rivals = math.hypot(u_rivals, u_aliases)
    if withdrawn is not None:
        # BIC prefers the withdrawn model, the halves contradict it: the data do not decide, and
        # its distance is carried whole
        rival = withdrawn.rival(w)
        rivals += (rival,)
        u_rivals = math.hypot(u_rivals, rival.delta)
    law, spent = law_rival(final, moves, prep, rig, f_scale) if withdrawn is None else (None, 0)
    nfev += spent
    if law is not None and law.d_bic < options.bic_margin:
        rival = law.rival(w)
        rivals += (rival,)
        u_rivals = math.hypot(u_rivals, math.sqrt(rival.weight) * rival.delta)
    form = ModelForm(segments, rivals, u_rivals)
    ambiguous = form.ambiguous(ws)
    w_u = math.sqrt(ws**2 + (w_cal or 0.0) ** 2 + form.u**2)
    J = _inertia(rig, w)
    J_std = None if J is None else 2 * J * ws / w
    J_cal = None
    if J is not None and (rig.restoring_constant_std or w_cal):
        J_cal = J * math.hypot((rig.restoring_constant_std or 0.0) / rig.restoring_constant, 2 * (w_cal or 0.0) / w)
    J_model = None if J is None else 2 * J * form.u / w
    budget = budgets(rig, w, ws, dof=float(final.dof), model=form.u, view=w_cal,
                     scale_response=_omega_n_per_scale(final) if rig.sensor_calibrated else None)
    J_u = budget["J"].u if "J" in budget else None
    J_obj = J_obj_std = J_ax = J_ax_std = None
    if J is not None and rig.tare_inertia is not None:
        J_obj = J - rig.tare_inertia
        J_obj_std = math.hypot(J_std or 0.0, rig.tare_inertia_std or 0.0)
    if J is not None and rig.object is not None:
        base_j = J_obj if J_obj is not None else J
        J_ax = base_j - rig.object.mass * rig.object.axis_offset**2
        J_ax_std = J_obj_std if J_obj is not None else J_std

    model = final.model
    amp_ref = float(np.max(np.abs(final.fitted - final.value("offset"))))

    def ratio(xx: np.ndarray) -> float:
        w = model.value(xx, "omega_n")
        c_eq = sum(e.equivalent_viscous(model.values(xx, e.name), amp_ref, w) for e in model.dynamic)
        return c_eq / (2 * w)

    zeta, zeta_std = _propagate(ratio, final.x, final.cov)

    flags: list[str] = list(trace.flags)
    # structure beyond the noise model is flagged when it matters: it changes the answer by more
    # than the fit's σ (the halves disagree), or it has a shape the report can name
    changes_answer = segments is not None and segments.disagree and segments.u > ws
    named = diag.named_structure()
    # far above the noise (where the loop's screen is not trusted either) a structured residual
    # is a model that misses the swing itself, whatever ω_n does
    far = prep.noise > 0 and final.residual_rms > SCREEN_TRUST * prep.noise
    # (a fit that does not follow the swing at all is a failed fit, not structure left: fit_not_converged)
    unmodeled = follows and diag.structured and (changes_answer or bool(named) or far)
    if unmodeled:
        flags.append(F.UNMODELED_RESIDUAL)
    if segments is not None and segments.disagree:
        flags.append(F.HALVES_DISAGREE)
    if ambiguous:
        flags.append(F.MODEL_AMBIGUOUS)
    if n_outliers:
        flags.append(F.OUTLIERS_REMOVED)
    if final.n_downweighted:
        flags.append(F.OUTLIERS_DOWNWEIGHTED)
    if prep.gap_cut_at is not None:
        flags.append(F.WINDOW_CUT_AT_GAP)
    if prep.n_unwrapped:
        flags.append(F.ANGLE_UNWRAPPED)
    if not final.success or not follows:
        flags.append(F.FIT_NOT_CONVERGED)
    effect_bounds = [n for n in final.at_bound if "." in n]
    if effect_bounds:
        flags.append(F.PARAMETER_AT_BOUND)
    if final.cov_method != "white":
        flags.append(F.CORRELATED_RESIDUAL)
    if any(v is not None and v < 0 for v in (J_obj, J_ax)):
        flags.append(F.NEGATIVE_INERTIA)

    added = tuple(n for n in final.model.effect_names if n not in declared.effect_names)
    structure = diag.describe()
    if segments is not None:
        (w1, w2), (s1, s2) = segments.omega_n, segments.omega_n_std
        verdict = ("they disagree: the model lacks something that changes with the amplitude or the time "
                   f"(flag halves_disagree); ±{segments.u:.2g} rad/s of model form enters omega_n_u"
                   if segments.disagree else "they agree")
        structure.append(f"the final model fitted to each half of the record (split at {segments.t_split:.3g} s) gives "
                         f"ω_n {w1:.6g} ± {s1:.2g} and {w2:.6g} ± {s2:.2g} rad/s ({segments.z:.1f} σ apart): {verdict}")
    else:
        structure.append("the record is too short to fit each half alone: whether the model holds across it is not checked")
    if beaten_by is not None:
        kept = ("refitted from that model's values" if final is not beaten_by else
                f"that model is kept ({', '.join(final.model.effect_names) or 'no effect'}): a refit from its values "
                "did not reach it")
        structure.append(
            f"the model {', '.join(slipped_from.model.effect_names)} ended with residual RMS "
            f"{slipped_from.residual_rms:.3g} rad, worse than the model it contains "
            f"({', '.join(beaten_by.model.effect_names) or 'no effect'}, {beaten_by.residual_rms:.3g} rad) on the same "
            f"samples: its fit had left the optimum; {kept}")
    if not follows:
        structure.append(
            f"the fit does not follow the swing: its residual RMS {final.residual_rms:.3g} rad is "
            f"{100 * follow_ratio:.0f} % of the fitted swing's RMS (limit {100 * FOLLOW_LIMIT:.0f} %) and "
            f"{final.residual_rms / prep.noise:.0f} × the noise floor; do not use this J (flag fit_not_converged)")
    if withdrawn is not None:
        ws_ = withdrawn.segments
        structure.append(
            f"{', '.join(withdrawn.effects)} lowered BIC by {-withdrawn.d_bic:.1f} but moved ω_n to "
            f"{withdrawn.omega_n:.6g} rad/s ({withdrawn.omega_n - w:+.2g}), and the model with it does not hold "
            f"across the record (halves {ws_.omega_n[0]:.6g} and {ws_.omega_n[1]:.6g} rad/s, {ws_.z:.1f} σ apart): "
            "it is not kept, its ω_n is a rival in omega_n_u (flag model_ambiguous)")
    if law is not None:
        verdict = ("the data do not separate them: its ω_n enters omega_n_u by its BIC weight"
                   if law.d_bic < options.bic_margin else "the data separate them: the effect stands")
        structure.append(
            f"{law.effect} changes how the swing's frequency depends on its amplitude, as a restoring law other than "
            f"the rig's would: fitted in its place, {law.law} (not offered on this rig) gives ω_n {law.omega_n:.6g} rad/s "
            f"({law.omega_n - w:+.2g}) at ΔBIC {law.d_bic:+.1f}; {verdict}")
    for c in rivals if ambiguous else ():
        if c.weight >= 0.05:
            structure.append(f"a rival explanation the data do not decisively reject: {c.change} (ΔBIC {c.d_bic:+.1f}, "
                             f"weight {c.weight:.2f}) gives ω_n {c.omega_n:.6g} rad/s ({c.delta:+.2g}); "
                             f"the spread enters omega_n_u (flag model_ambiguous)")
    if unmodeled:
        what = "; ".join(named) if named else ("it changes ω_n by more than the fit's σ" if changes_answer else
                                              f"the residual is over {SCREEN_TRUST:g} × the noise floor")
        structure.append(f"left unexplained: no effect of the library accounts for this structure ({what}; "
                         "flag unmodeled_residual)")
    elif diag.structured:
        structure.append("the rest is coloured noise: structure beyond the noise model that neither changes ω_n beyond "
                         "its σ nor has a shape to name")
    nominal = _omega_n_at_nominal_scale(final)
    if nominal is not None:
        flags.append(F.SENSOR_SCALE_FITTED)
        names, w_nom = nominal
        structure.append(f"the angle's scale was fitted from the swing ({', '.join(names)}): with the sensor at its "
                         f"nominal scale ω_n would read {w_nom:.6g} rad/s ({(w_nom - w) / ws:+.1f} σ, "
                         f"{100 * (w_nom - w) / w:+.2f} %); calibrate the sensor's scale (flag sensor_scale_fitted)")
    if F.CAMERA_PERSPECTIVE in flags:
        pattern = float((view or {}).get("distance_pattern", float("nan")))
        structure.append(f"the camera's view was more than oblique: the two markers' distance changed with the angle "
                         f"by up to {100 * pattern:.1f} % after the oblique view was removed (perspective, or a "
                         f"position-dependent tracker bias); the angle keeps an error of that kind and part of the "
                         f"residual may be it (flag camera_perspective)")
    statistics = {
        "n": final.n, "k": final.k, "dof": final.dof, "rss": final.rss,
        "chi2": final.rss / prep.noise**2, "redchi": final.rss / prep.noise**2 / max(final.dof, 1),
        "aic": final.aic, "bic": final.bic, "nfev": nfev, "success": final.success, "message": final.message,
        "covariance": final.cov_method, "covariance_inflation": final.cov_inflation,
        "noise_model_order": final.noise.order, "innovation_std": math.sqrt(final.noise.innovation_var),
        "robust_loss_scale": final.f_scale,
    }
    window = {
        "t_start": float(final.t[0]), "t_stop": float(final.t[-1]), "n_used": final.n, "n_total": len(trace),
        "n_outliers": n_outliers, "release_detected": prep.release_detected, "stop_detected": prep.stopped, "came_to_rest": prep.stuck,
        "n_downweighted": final.n_downweighted, "n_unwrapped": prep.n_unwrapped, "gap_cut_at": prep.gap_cut_at,
    }
    arrays = {
        "t": final.t, "angle": final.y, "fitted": final.fitted, "residual": final.residual,
        "baseline_fitted": base.fitted, "baseline_residual": base.residual,
        "trace_t": trace.t, "trace_angle": trace.angle,
    }
    return IdentificationResult(
        source=trace.source, rig_kind=rig.kind,
        J=J, J_std=J_std, J_std_calibration=J_cal, J_object=J_obj, J_object_std=J_obj_std,
        J_object_axis=J_ax, J_object_axis_std=J_ax_std,
        omega_n=w, omega_n_std=ws, omega_n_std_calibration=w_cal, omega_n_std_model=form.u, omega_n_u=w_u,
        J_std_model=J_model, J_u=J_u, model_form=form.to_dict(),
        uncertainty_budget={k: b.to_dict() for k, b in budget.items()}, damping_ratio=zeta, damping_ratio_std=zeta_std, reference_amplitude=amp_ref,
        offset=Quantity(final.value("offset"), final.stdev("offset"), "rad"),
        damping=_effect_quantities(final, rig, ("damping",)),
        stiffness=_effect_quantities(final, rig, ("stiffness",)),
        sensor=_effect_quantities(final, rig, ("sensor",)),
        declared_effects=declared.effect_names, effects=final.model.effect_names, added_effects=added,
        residual_rms=final.residual_rms, noise_floor=prep.noise, statistics=statistics, flags=tuple(dict.fromkeys(flags)),
        baseline=_summary(base, rig), steps=tuple(steps), diagnostics=diag.as_dict(), structure=tuple(structure),
        window=window, acquisition={k: v for k, v in trace.meta.items() if k != "truth"},
        sensor_calibrated=rig.sensor_calibrated, arrays=arrays,
    )
