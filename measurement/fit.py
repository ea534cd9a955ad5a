"""Whole-record fit of one model: starting values, least squares, uncertainties.

1. Starting values by equation error: θ, θ', θ'' from a Savitzky–Golay
   filter, then a bounded linear regression −θ'' = ω_n²·r(θ) + Σ p·φ(θ, θ')
   (every effect is linear in its normalised parameters). Falls back to
   zero crossings and the envelope when the regression is unusable.
2. Output error: nonlinear least squares of the simulated response against
   every sample (scipy ``least_squares``, trust-region reflective, bounds
   keep dissipation ≥ 0). The Jacobian is a forward difference of the
   simulation for the dynamic parameters and exact for the offset and the
   sensor terms, which enter linearly.
3. Covariance s²·(JᵀJ)⁻¹, replaced by a Newey–West (HAC) sandwich when the
   residual is autocorrelated: correlated residuals carry less information
   than their count suggests, and the plain formula would understate σ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, lsq_linear
from scipy.signal import savgol_filter

from .errors import IdentificationError
from .model import STATE_PARAMS, Model
from .signal import find_swings, resample_uniform


@dataclass(frozen=True, eq=False)
class ModelFit:
    """Outcome of fitting one model to the fitted samples (t, y)."""

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
    cov_method: str = "white"
    cov_inflation: float = 1.0
    at_bound: tuple[str, ...] = ()
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
        return float(math.sqrt(self.rss / self.n))

    @property
    def aic(self) -> float:
        return float(self.n * math.log(self.rss / self.n) + 2 * self.k)

    @property
    def bic(self) -> float:
        return float(self.n * math.log(self.rss / self.n) + self.k * math.log(self.n))

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    def value(self, name: str) -> float:
        return float(self.x[self.names.index(name)])

    def stdev(self, name: str) -> float:
        return float(self.std[self.names.index(name)])


# -- starting values ---------------------------------------------------------------


def _centre(t: np.ndarray, y: np.ndarray, sigma: float) -> float:
    sw = find_swings(t, y, hysteresis=3 * sigma)
    pv = sw.peak_values
    if pv.size >= 3:
        mids = 0.5 * (pv[:-1] + pv[1:])
        return sw.centre + float(np.median(mids))
    return sw.centre


def initial_guess(model: Model, t: np.ndarray, y: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Starting parameter vector and typical scales (for steps and x_scale), by equation error."""
    centre = _centre(t, y, sigma)
    sw = find_swings(t, y, centre=centre, hysteresis=3 * sigma)
    wd = sw.damped_frequency
    if not math.isfinite(wd) or wd <= 0:
        raise IdentificationError("no swing found: cannot estimate the frequency (fewer than two zero crossings)")
    tu, yu, dt = resample_uniform(t, y)
    period_samples = 2 * math.pi / wd / dt
    window = int(max(7, min(period_samples / 5.0, (tu.size // 3))))
    window += 1 - window % 2
    order = 4 if window > 7 else 3
    ys = savgol_filter(yu, window, order, mode="interp")
    yd = savgol_filter(yu, window, order, deriv=1, delta=dt, mode="interp")
    ydd = savgol_filter(yu, window, order, deriv=2, delta=dt, mode="interp")
    amplitude = float(np.max(np.abs(ys - centre)))
    theta0 = float(ys[0] - centre)
    omega0 = float(yd[0])

    sl = slice(window, max(window + 1, ys.size - window))
    xs, vs, acc = ys[sl] - centre, yd[sl], ydd[sl]
    restoring = np.sin(xs) if model.rig.kind == "compound" else xs
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
    try:
        sol = lsq_linear(A / col_rms, -acc, bounds=(lo, hi), method="bvls")
        coef = sol.x / col_rms
        regression_ok = bool(sol.success) and coef[0] > 0 and np.all(np.isfinite(coef))
    except (ValueError, np.linalg.LinAlgError):
        regression_ok = False
    if regression_ok and coef is not None:
        omega_n = math.sqrt(coef[0])
        # the regression is biased by noise on θ''; trust it only near ω_d
        if not 0.7 * wd < omega_n < 1.4 * wd:
            regression_ok = False
    if regression_ok and coef is not None:
        effect_values = list(coef[1:])
    else:
        omega_n = omega_guess
        effect_values = []
        for e in model.dynamic:
            effect_values += [0.0] * len(e.parameters)
        if model.dynamic and model.dynamic[0].name == "viscous" and sw.peak_values.size >= 4:
            amps = np.abs(sw.peak_values)
            good = amps > 10 * sigma
            if good.sum() >= 3:
                slope = np.polyfit(sw.peak_times[good], np.log(amps[good]), 1)[0]
                effect_values[0] = max(0.0, -2.0 * slope)

    x = [theta0, omega0, omega_n] + effect_values + [centre] + [0.0] * (len(model.names) - model.n_dynamic - 1)
    x = np.asarray(x, dtype=float)
    scales = [max(amplitude, 1e-6), max(amplitude * omega_n, 1e-6), omega_n]
    restoring_rms = omega_n**2 * float(np.sqrt(np.mean(restoring**2)))
    scales += list(restoring_rms / col_rms[1:])
    scales.append(max(amplitude, 1e-6))
    duration = float(t[-1] - t[0])
    for e in model.sensor:
        scales += [max(amplitude, 1e-6) / duration] * len(e.parameters)
    scales = np.asarray(scales, dtype=float)

    lo_b, hi_b = model.bounds()
    x = np.clip(x, lo_b, hi_b)
    return x, scales


def start_candidates(model: Model, x: np.ndarray, previous: "ModelFit | None") -> list[np.ndarray]:
    """Starting vectors worth trying: the regression's, and the previous fit's
    values overlaid on it (all of them, or only the initial state and the
    sensor terms). Adding an effect can move ω_n a lot (a hardening spring
    lowers the small-amplitude frequency), so neither start always wins."""
    starts = [x]
    if previous is None:
        return starts
    prev = dict(zip(previous.names, previous.x))
    lo_b, hi_b = model.bounds()
    full, state = x.copy(), x.copy()
    for i, name in enumerate(model.names):
        if name in prev:
            full[i] = prev[name]
            if i < 2 or i >= model.n_dynamic:
                state[i] = prev[name]
    starts += [np.clip(full, lo_b, hi_b), np.clip(state, lo_b, hi_b)]
    return starts
    return x, scales


# -- least squares --------------------------------------------------------------------


def fit_model(model: Model, t: np.ndarray, y: np.ndarray, sigma: float, *,
              x0: np.ndarray | None = None, scales: np.ndarray | None = None,
              previous: ModelFit | None = None, max_step: float | None = None,
              max_nfev: int = 200) -> ModelFit:
    """Fit ``model`` to every sample (t in s, y in rad); sigma: noise floor, rad."""
    starts = None
    if x0 is None or scales is None:
        x_reg, scales = initial_guess(model, t, y, sigma)
        starts = start_candidates(model, x_reg, previous)
        x0 = starts[0]
    lo, hi = model.bounds()
    nd = model.n_dynamic
    if max_step is None:
        amp = max(abs(x0[0]), float(np.max(np.abs(y - x0[nd]))))
        k3_ratio = 0.0
        if "cubic_stiffness" in model.effect_names:
            k3_ratio = max(0.0, model.split(x0)["cubic_stiffness"][0]) / max(x0[2], 1e-9) ** 2
        max_step = 0.05 / (x0[2] * math.sqrt(1 + 3 * k3_ratio * amp**2))
    lin_cols = model.sensor_columns(t)
    steps = 1e-7 * scales[:nd]
    nfev = [0]

    def simulate(x: np.ndarray) -> np.ndarray:
        nfev[0] += 1
        theta, _ = model.dynamics(x).integrate(t, x[0], x[1], x[2], max_step)
        return theta

    cache: dict[str, np.ndarray] = {}

    def fun(x: np.ndarray) -> np.ndarray:
        theta = simulate(x)
        cache["x"], cache["theta"] = x.copy(), theta
        return theta + lin_cols @ x[nd:] - y

    def jac(x: np.ndarray) -> np.ndarray:
        if "x" in cache and np.array_equal(cache["x"], x):
            base = cache["theta"]
        else:
            base = simulate(x)
        J = np.empty((t.size, x.size))
        for j in range(nd):
            xp = x.copy()
            h = steps[j]
            # step inwards at a bound so the perturbed model stays physical
            if xp[j] + h > hi[j]:
                h = -h
            xp[j] += h
            J[:, j] = (simulate(xp) - base) / h
        J[:, nd:] = lin_cols
        return J

    if starts is not None and len(starts) > 1:
        costs = [float(np.sum(fun(xs) ** 2)) for xs in starts]
        x0 = starts[int(np.argmin(costs))]
    try:
        sol = least_squares(fun, x0, jac=jac, bounds=(lo, hi), x_scale=scales, method="trf",
                            ftol=1e-12, xtol=1e-12, gtol=1e-10, max_nfev=max_nfev)
    except (ValueError, FloatingPointError, OverflowError, ZeroDivisionError) as exc:
        raise IdentificationError(f"least squares failed for model {model.effect_names}: {exc}") from exc
    x = sol.x
    residual = fun(x)
    if not np.all(np.isfinite(residual)):
        raise IdentificationError(f"model {model.effect_names} diverged (non-finite simulation)")
    J = jac(x)
    rss = float(residual @ residual)
    cov, method, inflation = covariance(J, residual, scales)
    tol = 1e-9 * scales
    at_bound = tuple(n for n, v, l, s in zip(model.names, x, lo, tol) if np.isfinite(l) and v - l <= s)
    return ModelFit(
        model=model, x=x, cov=cov, t=t, y=y, fitted=y + residual, residual=residual, rss=rss,
        success=bool(sol.success), message=str(sol.message), nfev=nfev[0], max_step=max_step,
        cov_method=method, cov_inflation=inflation, at_bound=at_bound,
    )


def autocorrelation(r: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocorrelation ρ(0..max_lag) of a residual (FFT, biased estimator)."""
    r = np.asarray(r, dtype=float) - np.mean(r)
    n = r.size
    nfft = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(r, nfft)
    ac = np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1]
    return ac / ac[0] if ac[0] > 0 else np.zeros(max_lag + 1)


def covariance(J: np.ndarray, residual: np.ndarray, scales: np.ndarray) -> tuple[np.ndarray, str, float]:
    """Parameter covariance; Newey–West when the residual is autocorrelated.

    Returns (cov, method, inflation) where inflation is the ratio of the
    HAC to the white-noise standard deviation of the first-ranked parameter
    (a measure of how much the correlation mattered).
    """
    n, k = J.shape
    Js = J * scales  # scaled for conditioning
    JtJ = Js.T @ Js
    try:
        inv = np.linalg.inv(JtJ)
    except np.linalg.LinAlgError:
        inv = np.linalg.pinv(JtJ)
    s2 = float(residual @ residual) / max(n - k, 1)
    white = inv * s2
    max_lag = min(n // 4, 4000)
    rho = autocorrelation(residual, max_lag)
    if abs(rho[1]) < 3.0 / math.sqrt(n):
        return white * np.outer(scales, scales), "white", 1.0
    below = np.flatnonzero(np.abs(rho[1:]) < 0.05)
    lag = int(min(max_lag, 2 * (below[0] + 1) if below.size else max_lag))
    g = Js * residual[:, None]
    # Γ_l(a, b) = Σ_t g[t+l, a]·g[t, b] for all lags at once, via FFT
    nfft = 1 << (2 * n - 1).bit_length()
    F = np.fft.rfft(g, nfft, axis=0)
    C = np.fft.irfft(F[:, :, None] * np.conj(F[:, None, :]), nfft, axis=0)[: lag + 1]
    w = 1.0 - np.arange(1, lag + 1) / (lag + 1.0)
    cross = np.tensordot(w, C[1:], axes=(0, 0))
    S = C[0] + cross + cross.T
    hac = inv @ S @ inv * (n / max(n - k, 1))
    cov = hac * np.outer(scales, scales)
    d_white, d_hac = np.diag(white), np.diag(hac)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.sqrt(np.where(d_white > 0, d_hac / d_white, 1.0))
    return cov, "newey-west", float(np.max(ratios))
