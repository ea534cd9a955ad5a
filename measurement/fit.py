"""Whole-record fit of one model: starting values, least squares, noise model, uncertainties.

1. Starting values by equation error: θ, θ', θ'' from a Savitzky–Golay
   filter, then a bounded linear regression −θ'' = ω_n²·r(θ) + Σ p·φ(θ, θ')
   (every effect is linear in its normalised parameters). Falls back to
   zero crossings and each effect's own fallback when the regression is
   unusable.
2. Output error: nonlinear least squares of the simulated response against
   every sample (scipy ``least_squares``, trust-region reflective, bounds
   keep dissipation ≥ 0), optionally with a robust loss (soft-L1) so that a
   few wild samples cannot steer the fit. The Jacobian is a forward
   difference of the simulation for the dynamic parameters and exact for the
   offset and the sensor terms, which enter linearly.
3. The residual's noise model (``noise.fit_noise``, AR(p) with the order
   chosen by the data) gives the likelihood (BIC) and the covariance: the
   sandwich with the AR covariance, which reduces to s²·(JᵀJ)⁻¹ when the
   residual is white.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares, lsq_linear

from .errors import IdentificationError
from .model import STATE_PARAMS, Model
from .noise import NoiseModel, autocorrelation, fit_noise
from .restoring import restoring_column
from .signal import Swings, find_swings, periodogram, resample_uniform, savitzky_golay

__all__ = ["ModelFit", "Smoothed", "fit_model", "initial_guess", "smooth", "autocorrelation"]


@dataclass(frozen=True, eq=False)
class ModelFit:
    """Outcome of fitting one model to the fitted samples (t, y).

    residual: y_model − y (rad); effective: the residual as the loss sees it
    (equal to residual without a robust loss; wild samples shrunk with one);
    noise: the AR noise model of ``effective``; jac: the Jacobian (rad per
    parameter unit) at the solution.
    """

    model: Model
    x: np.ndarray
    cov: np.ndarray
    t: np.ndarray
    y: np.ndarray
    fitted: np.ndarray
    residual: np.ndarray
    rss: float
    success: bool
    message: str
    nfev: int
    max_step: float
    noise: NoiseModel
    effective: np.ndarray
    jac: np.ndarray
    scales: np.ndarray
    cov_method: str = "white"
    cov_inflation: float = 1.0
    at_bound: tuple[str, ...] = ()
    f_scale: float | None = None
    n_downweighted: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return self.model.names

    @property
    def n(self) -> int:
        return int(self.y.size)

    @property
    def k(self) -> int:
        return int(self.x.size)

    @property
    def dof(self) -> int:
        return self.n - self.k

    @property
    def residual_rms(self) -> float:
        return float(math.sqrt(float(self.residual @ self.residual) / self.n))

    @property
    def log_likelihood_term(self) -> float:
        """n·log σ_e² (−2·log-likelihood up to a constant) under the AR noise model."""
        return float(self.n * math.log(max(self.noise.innovation_var, 1e-300)))

    @property
    def n_params(self) -> int:
        """Model parameters plus the noise model's AR coefficients."""
        return self.k + self.noise.order

    @property
    def aic(self) -> float:
        return self.log_likelihood_term + 2 * self.n_params

    @property
    def bic(self) -> float:
        return self.log_likelihood_term + self.n_params * math.log(self.n)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    def value(self, name: str) -> float:
        """A scalar parameter by name: "omega_n", "offset", "theta0", "coulomb.Tc_per_J", ..."""
        return self.model.value(self.x, name)

    def stdev(self, name: str) -> float:
        return float(self.std[self.model.index(name)])

    def effect(self, name: str) -> list[float]:
        """An effect's fitted values (its ``parameters`` order)."""
        return self.model.values(self.x, name)


# -- starting values ---------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Smoothed:
    """What the starting values read from the samples (t, y), whatever the model: computed once
    for every model fitted to the same samples (a discovery round fits several).

    centre: the swing's centre line (rad); swings: about it; ys, yd, ydd:
    θ, θ', θ'' on the even grid of spacing dt (s) from a Savitzky–Golay
    filter of ``window`` samples (ydd only away from the ends, the only part read).
    supported: per grid point, whether the filter's window there spans measured samples
    only, not a straight line drawn across a gap in the record (None: the record is even).
    omega_d: the swing's damped angular frequency, rad/s: the swings' own (zero crossings) on
    an even record; on one with gaps, the least-squares periodogram's near it.
    peaks: on a record with gaps, the periodogram's comparable peaks over a wide band (rad/s,
    tallest first): frequencies the samples may not tell from the swing's (aliases); () on an even record.
    """

    t: np.ndarray
    y: np.ndarray
    sigma: float
    centre: float
    swings: Swings
    dt: float
    window: int
    ys: np.ndarray
    yd: np.ndarray
    ydd: np.ndarray
    supported: np.ndarray | None = None
    omega_d: float = float("nan")
    peaks: tuple[float, ...] = ()

    def holds(self, t: np.ndarray, y: np.ndarray, sigma: float) -> bool:
        """Whether this was computed from these very samples and noise floor."""
        return self.t is t and self.y is y and self.sigma == sigma


def _centre(t: np.ndarray, y: np.ndarray, sigma: float, sw: Swings | None = None) -> float:
    sw = find_swings(t, y, hysteresis=3 * sigma) if sw is None else sw
    pv = sw.peak_values
    if pv.size >= 3:
        mids = 0.5 * (pv[:-1] + pv[1:])
        return sw.centre + float(np.median(mids))
    return sw.centre


def smooth(t: np.ndarray, y: np.ndarray, sigma: float, swings: Swings | None = None) -> Smoothed:
    """The model-independent part of ``initial_guess``; swings: ``find_swings(t, y, hysteresis=3 * sigma)``
    when the caller has it."""
    centre = _centre(t, y, sigma, swings)
    sw = find_swings(t, y, centre=centre, hysteresis=3 * sigma)
    wd = sw.damped_frequency
    if not math.isfinite(wd) or wd <= 0:
        raise IdentificationError("no swing found: cannot estimate the frequency (fewer than two zero crossings)")
    tu, yu, dt = resample_uniform(t, y)
    period_samples = 2 * math.pi / wd / dt
    window = int(max(7, min(period_samples / 5.0, (tu.size // 3))))
    window += 1 - window % 2
    order = 4 if window > 7 else 3
    ys = savitzky_golay(yu, window, order)
    yd = savitzky_golay(yu, window, order, deriv=1, delta=dt)
    # θ'' is read only a window away from the ends, where every mode gives the same
    # convolution: no polynomial fits of the ends
    ydd = savitzky_golay(yu, window, order, deriv=2, delta=dt, ends="zero")
    supported = _supported(t, tu, dt, window)
    peaks: tuple[float, ...] = ()
    if supported is not None:
        # crossings are read off lines drawn across the gaps: weigh the samples themselves. Lines
        # across the gaps also hide crossings (ω_d of the crossings reads low, at times 4× low):
        # the peaks over a wide band are each a frequency the swing may have
        pg = periodogram(t, y, 0.25 * wd, 4.0 * wd)
        peaks = tuple(pg.peaks())
        wd = pg.frequency(0.5 * wd, 2.0 * wd)
    return Smoothed(t, y, sigma, centre, sw, dt, window, ys, yd, ydd, supported, wd, peaks)


def _supported(t: np.ndarray, tu: np.ndarray, dt: float, window: int) -> np.ndarray | None:
    """Grid points whose filter window holds no interpolated stretch longer than half the window (None: all).

    Across a gap the even grid carries a straight line: its θ'' is zero and its θ' constant,
    so an equation-error regression over it reads a wrong ω_n (a record from a lossy link,
    dense bursts between 0.4 s silences, started the fit 10 % off and it slipped a cycle).
    """
    if tu is t:
        return None
    i = np.clip(np.searchsorted(t, tu), 1, t.size - 1)
    # a few missing samples are bridged harmlessly: the filter's polynomial spans them anyway
    bridged = (t[i] - t[i - 1]) > max(2.0, 0.5 * window) * dt
    if not bridged.any():
        return None
    near = np.convolve(bridged.astype(float), np.ones(window), mode="same") > 0
    return ~near


def initial_guess(model: Model, t: np.ndarray, y: np.ndarray, sigma: float,
                  smoothed: Smoothed | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Starting parameter vector and typical scales (for steps and x_scale), by equation error.

    smoothed: ``smooth(t, y, sigma)`` when the caller has it.
    """
    if smoothed is None or not smoothed.holds(t, y, sigma):
        smoothed = smooth(t, y, sigma)
    centre, sw, window = smoothed.centre, smoothed.swings, smoothed.window
    wd = smoothed.omega_d
    if model.measures == "rate":
        centre, angle, rate, accel, sw = _from_rate(smoothed)
    else:
        angle, rate, accel = smoothed.ys - centre, smoothed.yd, smoothed.ydd
    amplitude = float(np.max(np.abs(angle)))
    theta0 = float(angle[0])
    omega0 = float(rate[0])

    sl = slice(window, max(window + 1, angle.size - window))
    rows = np.arange(angle.size)[sl]
    regress = True
    if smoothed.supported is not None:
        kept = rows[smoothed.supported[rows]]
        # too few rows between the gaps: ω_n starts at the swings' ω_d instead of a regression
        regress = kept.size >= 2 * window + len(model.dynamic) + 3
        rows = kept if regress else rows
    xs, vs, acc = angle[rows], rate[rows], accel[rows]
    restoring = restoring_column(model.rig.kind, xs, vs, acc, model.rig.geometry)
    columns = [restoring[:, None]] + [e.basis(xs, vs) for e in model.dynamic]
    A = np.hstack(columns)
    lo_b, hi_b = model.bounds()
    lo = np.concatenate([[0.0], lo_b[len(STATE_PARAMS):model.n_dynamic]])
    hi = np.full(lo.size, np.inf)
    # scales: the parameter value whose term is as large as the restoring one
    col_rms = np.sqrt(np.mean(A**2, axis=0))
    col_rms[col_rms == 0] = 1.0
    omega_guess = wd
    regression_ok = False
    coef = None
    if regress:
        try:
            sol = lsq_linear(A / col_rms, -acc, bounds=(lo, hi), method="bvls")
            coef = sol.x / col_rms
            regression_ok = bool(sol.success and coef[0] > 0 and np.all(np.isfinite(coef)))
        except (ValueError, np.linalg.LinAlgError):
            regression_ok = False
    if regression_ok and coef is not None:
        omega_n = math.sqrt(coef[0])
        # the regression is biased by noise on θ''; trust it only near ω_d (closer with gaps,
        # where fewer rows hold it and the periodogram's ω_d is the sharper figure)
        near = (0.7, 1.4) if smoothed.supported is None else (0.9, 1.15)
        if not near[0] * wd < omega_n < near[1] * wd:
            regression_ok = False
    values: dict[str, list[float]] = {}
    if regression_ok and coef is not None:
        i = 1
        for e in model.dynamic:
            values[e.name] = list(coef[i:i + len(e.parameters)])
            i += len(e.parameters)
    else:
        omega_n = omega_guess
        amps = np.abs(sw.peak_values)
        # well above the noise as the sensor reads them (a rate sensor reads ω·amplitude)
        good = amps * (wd if model.measures == "rate" else 1.0) > 10 * sigma
        for e in model.dynamic:
            start = e.fallback_start(sw.peak_times[good], amps[good]) if good.sum() >= 3 else None
            values[e.name] = start if start is not None else [0.0] * len(e.parameters)
    peaks = np.abs(sw.peak_values)
    smallest = float(np.min(peaks[-3:])) if peaks.size else amplitude
    for e in model.dynamic:
        if e.refines is not None:
            # a parameter the regression cannot see starts where it shows
            starts = e.refined_start(values[e.name][:1], (amplitude, smallest))
            values[e.name] = starts[len(starts) // 2]

    x = model.vector((theta0, omega0, omega_n), values, centre)
    restoring_rms = omega_n**2 * float(np.sqrt(np.mean(restoring**2)))
    scales = np.empty(model.size)
    scales[:3] = [max(amplitude, 1e-6), max(amplitude * omega_n, 1e-6), omega_n]
    scales[3:model.n_dynamic] = restoring_rms / col_rms[1:]
    for e in model.dynamic:
        sl = model.layout[e.name]
        scales[sl] = [s if size is None else size for s, size in zip(scales[sl], e.parameter_scales(amplitude))]
    # the swing's size as the sensor reads it: an angle, or a rate
    reading = amplitude * (omega_n if model.measures == "rate" else 1.0)
    scales[model.layout["offset"]] = max(reading, 1e-6)
    for e in model.sensor:
        # a sensor term of the swing's size over the record
        size = e.sensor_basis(t - t[0], np.full(t.size, reading))
        scales[model.layout[e.name]] = max(reading, 1e-6) / np.maximum(np.max(np.abs(size), axis=0), 1e-12)
    lo_b, hi_b = model.bounds()
    x = np.clip(x, lo_b, hi_b)
    return x, scales


def _from_rate(smoothed: Smoothed) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, Swings]:
    """(zero, θ, θ', θ'', swings of θ) on the even grid, from a rate sensor's smoothed reading (rad/s).

    The rate's centre line is the sensor's zero; the angle is the rate integrated, its
    constant and the ramp that a zero off by δ leaves (δ·t) taken out by the line through
    the midpoints of its successive turning points (only starting values: the fit takes
    the zero as a parameter, and never reads this integral).
    """
    rate = smoothed.ys - smoothed.centre
    tu = smoothed.t[0] + smoothed.dt * np.arange(rate.size)
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * smoothed.dt)])
    sw = find_swings(tu, angle)
    pv, pt = sw.peak_values, sw.peak_times
    slope = 0.0
    if pv.size >= 4:
        mids, when = 0.5 * (pv[:-1] + pv[1:]) + sw.centre, 0.5 * (pt[:-1] + pt[1:])
        slope, level = np.polyfit(when, mids, 1)
        angle = angle - (level + slope * tu)
    else:
        angle = angle - sw.centre
    return smoothed.centre + float(slope), angle, rate - slope, smoothed.yd, find_swings(tu, angle, centre=0.0)


def start_candidates(model: Model, x: np.ndarray, previous: "ModelFit | None") -> list[np.ndarray]:
    """Starting vectors worth trying: the regression's, and the previous fit's
    values overlaid on it (all of them, or only the initial state and the
    sensor terms). Adding an effect can move ω_n a lot (a hardening spring
    lowers the small-amplitude frequency), so neither start always wins."""
    starts = [x]
    if previous is None:
        return starts
    lo_b, hi_b = model.bounds()
    full, state = x.copy(), x.copy()
    pm = previous.model
    for name in ("theta0", "omega0", "omega_n", "offset"):
        full[model.index(name)] = previous.value(name)
        if name != "omega_n":
            state[model.index(name)] = previous.value(name)
    for e in pm.effects:
        if e.name in model.layout:
            full[model.layout[e.name]] = previous.effect(e.name)
            if e.role == "sensor":
                state[model.layout[e.name]] = previous.effect(e.name)
    starts += [np.clip(full, lo_b, hi_b), np.clip(state, lo_b, hi_b)]
    refining = [(e, e.refines) for e in model.effects if e.refines is not None and e.refines in pm.layout]
    if refining:
        # start from the fit it refines: the same values, the new parameters at sizes worth trying
        theta = np.abs(previous.extra["theta"])
        amplitudes = (float(np.max(theta)), float(np.max(theta[-max(1, theta.size // 10):])))
        for e, refined in refining:
            for vals in e.refined_start(previous.effect(refined), amplitudes):
                x_ref = full.copy()
                x_ref[model.layout[e.name]] = vals
                starts.append(np.clip(x_ref, lo_b, hi_b))
    return starts


# -- least squares --------------------------------------------------------------------


def fit_model(model: Model, t: np.ndarray, y: np.ndarray, sigma: float, *,  # noqa: C901
              x0: np.ndarray | None = None, scales: np.ndarray | None = None,
              previous: ModelFit | None = None, max_step: float | None = None,
              max_nfev: int = 200, f_scale: float | None = None, swings: Swings | None = None) -> ModelFit:
    """Fit ``model`` to every sample (t in s, y the sensor's reading: rad, or rad/s on a rate sensor);
    sigma: noise floor, in y's unit.

    f_scale: with a value (rad), a robust soft-L1 loss: residuals well beyond
    f_scale count in proportion to their size rather than its square.
    swings: ``find_swings(t, y, hysteresis=3 * sigma)`` when the caller has it.
    The starting values' model-independent part (``smooth``) is taken from
    ``previous`` when that was fitted to the very same samples.
    """
    starts = None
    smoothed = previous.extra.get("smoothed") if previous is not None else None
    if x0 is None or scales is None:
        if smoothed is None or not smoothed.holds(t, y, sigma):
            smoothed = smooth(t, y, sigma, swings)
        x_reg, scales = initial_guess(model, t, y, sigma, smoothed)
        starts = start_candidates(model, x_reg, previous)
        x0 = starts[0]
    lo, hi = model.bounds()
    nd = model.n_dynamic
    if max_step is None:
        max_step = model.max_step(x0, model.amplitude(x0, y))
    ts = t - t[0]
    steps = 1e-7 * scales[:nd]
    nfev = [0]

    # The last few evaluations by x: scipy evaluates the residual and the
    # Jacobian at the solution before it returns, the starting-value choice
    # evaluates the start least_squares begins with, and the fit's outputs
    # need both at the solution again; each is simulated once. Copies go
    # out: a robust loss scales scipy's arrays in place.
    evaluated: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # x → (measured, θ, θ')
    last_jac: dict[bytes, np.ndarray] = {}

    def simulate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        nfev[0] += 1
        return model.true_angle(x, t, max_step)

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        key = x.tobytes()
        hit = evaluated.get(key)
        if hit is None:
            theta, omega = simulate(x)
            hit = (model.measured(x, ts, theta, omega), theta, omega)
            if len(evaluated) >= 4:
                del evaluated[next(iter(evaluated))]
            evaluated[key] = hit
        return hit

    def fun(x: np.ndarray) -> np.ndarray:
        return evaluate(x)[0] - y

    def jac(x: np.ndarray) -> np.ndarray:
        key = x.tobytes()
        if key in last_jac:
            return last_jac[key].copy()
        base, theta, omega = evaluate(x)
        J = np.empty((t.size, x.size))
        for j in range(nd):
            xp = x.copy()
            h = steps[j]
            # step inwards at a bound so the perturbed model stays physical
            if xp[j] + h > hi[j]:
                h = -h
            xp[j] += h
            J[:, j] = (model.measured(xp, ts, *simulate(xp)) - base) / h
        J[:, nd:] = model.sensor_columns(ts, model.reading(theta, omega))
        last_jac.clear()
        last_jac[key] = J.copy()
        return J

    order = [0]
    if starts is not None and len(starts) > 1:
        costs = [float(np.sum(fun(xs) ** 2)) for xs in starts]
        order = [int(i) for i in np.argsort(costs)]
    loss = "linear" if f_scale is None else "soft_l1"
    # A model that contains the previous one fits the same samples at least as well; ending
    # worse, the solver went down another basin from the cheapest start (over a long record
    # a start near a poor fit can slip a cycle): the other starts are tried, the best kept.
    beaten = None
    if previous is not None and previous.f_scale == f_scale and previous.t.size == t.size and np.array_equal(previous.t, t):
        beaten = 0.5 * previous.rss * (1.0 + 1e-6)
    sol = None
    failed: Exception | None = None
    for i in order:
        x0 = starts[i] if starts is not None else x0
        try:
            trial = least_squares(fun, x0, jac=jac, bounds=(lo, hi), x_scale=scales, method="trf",
                                  ftol=1e-12, xtol=1e-12, gtol=1e-10, max_nfev=max_nfev,
                                  loss=loss, f_scale=1.0 if f_scale is None else f_scale)
        except (ValueError, FloatingPointError, OverflowError, ZeroDivisionError, np.linalg.LinAlgError) as exc:
            failed = exc
            continue
        if sol is None or trial.cost < sol.cost:
            sol = trial
        if beaten is None or sol.cost <= beaten:
            break
    if sol is None:
        raise IdentificationError(f"least squares failed for model {model.effect_names}: {failed}") from failed
    x = sol.x
    _, theta, omega = evaluate(x)
    residual = fun(x)
    if not np.all(np.isfinite(residual)):
        raise IdentificationError(f"model {model.effect_names} diverged (non-finite simulation)")
    J = jac(x)
    effective, weight = robust_residual(residual, f_scale)
    noise = fit_noise(effective)
    cov, method, inflation = covariance(J * np.sqrt(weight)[:, None], effective, scales, noise)
    tol = 1e-9 * scales
    at_bound = tuple(n for n, v, l, u, s in zip(model.names, x, lo, hi, tol)
                     if (np.isfinite(l) and v - l <= s) or (np.isfinite(u) and u - v <= s))
    return ModelFit(
        model=model, x=x, cov=cov, t=t, y=y, fitted=y + residual, residual=residual,
        rss=float(effective @ effective), success=bool(sol.success), message=str(sol.message), nfev=nfev[0],
        max_step=max_step, noise=noise, effective=effective, jac=J, scales=scales,
        cov_method=method, cov_inflation=inflation, at_bound=at_bound, f_scale=f_scale,
        n_downweighted=int(np.sum(weight < 0.5)),
        # the true swing at x (rad, rad/s); what the starting values read from (t, y), for the next model
        extra={"theta": theta, "omega": omega, "smoothed": smoothed},
    )


def swing_amplitude(fit: ModelFit) -> float:
    """The fitted swing's largest angle, rad: as the sensor reads it about its zero (an angle sensor's
    terms included), or on a rate sensor, whose reading is a rate, the true swing's."""
    if fit.model.measures == "rate":
        return float(np.max(np.abs(fit.extra["theta"])))
    return float(np.max(np.abs(fit.fitted - fit.value("offset"))))


def robust_residual(residual: np.ndarray, f_scale: float | None) -> tuple[np.ndarray, np.ndarray]:
    """(effective residual, weight) of the soft-L1 loss ρ(z) = 2(√(1+z) − 1), z = (r/f)².

    The effective residual sign(r)·f·√ρ has the loss as its sum of squares (so
    the noise model and BIC see what the fit minimised); the weight ρ'(z) =
    1/√(1+z) is the share of a sample's information the fit used.
    """
    if f_scale is None:
        return residual, np.ones_like(residual)
    z = (residual / f_scale) ** 2
    rho = 2.0 * (np.sqrt(1.0 + z) - 1.0)
    return np.sign(residual) * f_scale * np.sqrt(rho), 1.0 / np.sqrt(1.0 + z)


def _inverse_gram(Js: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁻¹ of a scaled Jacobian (the pseudo-inverse when it is singular)."""
    JtJ = Js.T @ Js
    try:
        return np.linalg.inv(JtJ)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(JtJ)


def _coloured_gram(Js: np.ndarray, blocks: Sequence[tuple[slice, NoiseModel, float]]) -> np.ndarray:
    """JᵀΣJ for rows in independent blocks, each with its own AR noise model and the parameters
    charged to it (its degrees of freedom): Σ_b σ_e²·‖A_b⁻ᵀJ_b‖²·n_b/(n_b − k_b)."""
    middle = np.zeros((Js.shape[1], Js.shape[1]))
    for rows, noise, k in blocks:
        G = noise.colour_t(Js[rows])
        n = G.shape[0]
        middle += noise.innovation_var * (G.T @ G) * (n / max(n - k, 1))
    return middle


def block_covariance(J: np.ndarray, scales: np.ndarray,
                     blocks: Sequence[tuple[slice, NoiseModel, float]]) -> np.ndarray:
    """Parameter covariance of a least-squares estimate over several independent stretches of samples
    (rows of J), each with its own AR noise model: the sandwich of ``covariance`` block by block."""
    Js = J * scales
    inv = _inverse_gram(Js)
    return (inv @ _coloured_gram(Js, blocks) @ inv) * np.outer(scales, scales)


def covariance(J: np.ndarray, residual: np.ndarray, scales: np.ndarray,
               noise: NoiseModel | None = None) -> tuple[np.ndarray, str, float]:
    """Parameter covariance of the least-squares estimate under the AR noise model.

    cov = (JᵀJ)⁻¹·JᵀΣJ·(JᵀJ)⁻¹ with Σ = σ_e²·A⁻¹A⁻ᵀ (``noise``); for white
    noise this is s²·(JᵀJ)⁻¹. Returns (cov, method, inflation): method
    "white" or "ar(p)", inflation the largest ratio of a σ to its white-noise value.
    """
    n, k = J.shape
    Js = J * scales  # scaled for conditioning
    inv = _inverse_gram(Js)
    if noise is None:
        noise = fit_noise(residual)
    s2 = float(residual @ residual) / max(n - k, 1)
    white = inv * s2
    if noise.order == 0:
        return white * np.outer(scales, scales), "white", 1.0
    sandwich = inv @ _coloured_gram(Js, [(slice(None), noise, k)]) @ inv
    d_white, d_ar = np.diag(white), np.diag(sandwich)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.sqrt(np.where(d_white > 0, d_ar / d_white, 1.0))
    return sandwich * np.outer(scales, scales), f"ar({noise.order})", float(np.max(ratios))
