"""What a residual says: size against the noise floor, and its structure.

The numbers here decide when the discovery loop stops (residual at the
noise floor and white) and what the report says about a residual the model
library cannot explain. Each effect reads them in ``evidence`` to say why it
is a plausible cause. They are computed here (``diagnose``); the record of
them and its words, which a result carries, is ``measurement.residual``.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from .fit import ModelFit
from .noise import autocorrelation, fit_noise, ljung_box
from .residual import Diagnostics
from .signal import find_swings, resample_uniform


def _envelope_law(times: np.ndarray, amps: np.ndarray) -> tuple[str | None, dict]:
    """Which decay law fits the peak amplitudes best: exponential, linear, hyperbolic."""
    if amps.size < 5:
        return None, {}
    laws: dict[str, tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]] = {  # law: (linearised A, back to A)
        "exponential (viscous)": (np.log(amps), np.exp),
        "linear (coulomb)": (amps, lambda v: v),
        "hyperbolic (quadratic drag)": (1.0 / amps, lambda v: 1.0 / v),
    }
    errors: dict[str, float] = {}  # law's first word: relative RMS misfit of the amplitudes
    for law, (z, back) in laws.items():
        coef = np.polyfit(times, z, 1)
        lin = np.polyval(coef, times)
        if law.startswith("hyperbolic") and np.any(lin <= 0):
            errors[law.split(" ")[0]] = math.inf  # 1/A crossing zero: the law does not apply
            continue
        pred = back(lin)
        errors[law.split(" ")[0]] = float(np.sqrt(np.mean((pred - amps) ** 2)) / np.mean(amps))
    best = min(errors, key=errors.__getitem__)
    runner_up = min(v for k, v in errors.items() if k != best)
    # Over a small decay the three laws look alike; name one only when the
    # amplitude fell by a third and the best law fits clearly better.
    if amps.min() > 0.67 * amps.max() or errors[best] > 0.5 * runner_up:
        return None, errors
    full = next(k for k in laws if k.startswith(best))
    return full, errors


def _slope_t(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    if x.size < 4 or np.ptp(x) == 0:
        return 0.0, 0.0
    A = np.vstack([x, np.ones_like(x)]).T
    coef, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    s2 = float(resid @ resid) / max(x.size - 2, 1)
    var = s2 / float(np.sum((x - x.mean()) ** 2))
    se = math.sqrt(var) if var > 0 else 0.0
    return float(coef[0]), float(coef[0] / se) if se > 0 else 0.0


def _decrement(peaks: np.ndarray) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Fit ΔA = d0 + d1·A + d2·A² to the loss over each full swing (peak i to i+2)."""
    a = np.abs(peaks)
    if a.size < 8:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    loss = a[:-2] - a[2:]
    amp = 0.5 * (a[:-2] + a[2:])
    # over a narrow amplitude range 1, A and A² are nearly collinear: keep
    # the quadratic term only when the amplitude fell by 3× or more
    wide = amp.max() >= 3.0 * amp.min()
    X = np.vstack([np.ones_like(amp), amp, amp**2 if wide else np.zeros_like(amp)]).T
    coef, *_ = np.linalg.lstsq(X, loss, rcond=None)
    resid = loss - X @ coef
    dof = max(loss.size - 3, 1)
    try:
        cov = float(resid @ resid) / dof * np.linalg.pinv(X.T @ X)
    except np.linalg.LinAlgError:
        return _three(coef), (0.0, 0.0, 0.0)
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    tv = np.where(se > 0, coef / np.where(se > 0, se, 1.0), 0.0)
    return _three(coef), _three(tv)


def _three(v: np.ndarray) -> tuple[float, float, float]:
    return float(v[0]), float(v[1]), float(v[2])


def structure_test(fit: ModelFit, line_hz: float | None) -> tuple[float, float]:
    """ΔBIC of explaining the residual by the shapes an unmodelled effect leaves, under an AR noise model,
    and ΔBIC of the envelope shapes alone (θ·τ, θ·τ²).

    The shapes: the fitted swing θ and its rate θ' modulated by 1, τ, τ²
    (an envelope or a frequency the model gets wrong), θ² and θ³
    (asymmetry, amplitude-dependent distortion), τ, τ², τ³ (a slow sensor
    trend) and a sinusoid with a linear envelope at the residual's spectral
    peak (another mode, a vibration); τ is time over the record. The AR
    noise model is fitted to the residual left after them, so it cannot
    absorb them; coloured noise alone gains only what chance gives, far
    below the penalty of log n per shape.
    """
    t, r = fit.t, fit.effective
    n = r.size
    span = max(float(t[-1] - t[0]), 1e-12)
    tau = (t - t[0]) / span
    theta = fit.fitted - fit.value("offset")
    rate = np.gradient(theta, t)
    amp = max(float(np.max(np.abs(theta))), 1e-12)
    rate_scale = max(float(np.max(np.abs(rate))), 1e-12)
    peak_hz = line_hz if line_hz is not None and line_hz > 0 else None
    # the columns written in place: a list of 11 to 15 arrays stacked would be copied once more
    X = np.empty((n, 11 if peak_hz is None else 15))
    a, w = theta / amp, rate / rate_scale
    tau2 = tau * tau
    X[:, 0], X[:, 1], X[:, 2] = a, a * tau, a * tau2
    X[:, 3], X[:, 4], X[:, 5] = w, w * tau, w * tau2
    X[:, 6], X[:, 7] = a * a, a * a * a
    X[:, 8], X[:, 9], X[:, 10] = tau, tau2, tau2 * tau
    if peak_hz is not None:
        arg = 2 * math.pi * peak_hz * (t - t[0])
        c, s = np.cos(arg), np.sin(arg)
        X[:, 11], X[:, 12], X[:, 13], X[:, 14] = c, s, tau * c, tau * s
    X -= X.mean(axis=0)
    rc = r - r.mean()
    left = _fit_residual(X, rc)
    noise = fit_noise(left)
    Xw, rw = noise.whiten(X), noise.whiten(rc)
    ew = _fit_residual(Xw, rw)
    m = rw.size
    # the swing's envelope alone (θ·τ, θ·τ²: an amplitude the model loses too fast or too slowly),
    # under the same noise model: a damping law the model lacks
    env = _fit_residual(Xw[:, 1:3], rw)
    with np.errstate(divide="ignore"):
        base = max(float(rw @ rw), 1e-300)
        gain = m * math.log(max(float(ew @ ew), 1e-300) / base)
        gain_env = m * math.log(max(float(env @ env), 1e-300) / base)
    return (float(gain + (X.shape[1] + (1 if line_hz is not None else 0)) * math.log(n)),
            float(gain_env + 2 * math.log(n)))


def _fit_residual(X: np.ndarray, b: np.ndarray) -> np.ndarray:
    """b minus its least-squares fit on the columns of X, as ``np.linalg.lstsq`` leaves it.

    Tall and thin X (samples × 11–15 shapes): by the normal equations of the
    equilibrated Gram matrix, refined once, a quarter of the SVD's cost;
    the residual is then the SVD's to round-off (its error is second order
    in the coefficients'). When X is ill conditioned (cond > 1e5), or the
    Gram matrix is unusable, by the SVD itself.
    """
    G = X.T @ X
    d = np.sqrt(np.diag(G))
    if np.all(d > 0) and np.all(np.isfinite(G)):
        Gs = G / np.outer(d, d)
        ev = np.linalg.eigvalsh(Gs)
        if ev[0] > 1e-10 * ev[-1]:
            try:
                cf = cho_factor(Gs, check_finite=False)
            except np.linalg.LinAlgError:
                cf = None
            if cf is not None:
                c = cho_solve(cf, (X.T @ b) / d, check_finite=False)
                e = b - X @ (c / d)
                c += cho_solve(cf, (X.T @ e) / d, check_finite=False)
                return b - X @ (c / d)
    coef, *_ = np.linalg.lstsq(X, b, rcond=None)
    return b - X @ coef


def diagnose(fit: ModelFit, noise: float, stopped: bool = False) -> Diagnostics:
    """Diagnostics of ``fit``'s residual; noise: the noise floor estimated from the data, rad."""
    r = fit.residual
    n = r.size
    rms = fit.residual_rms
    ratio = rms / noise if noise > 0 else math.inf
    lags = int(min(20, max(2, n // 10)))
    rho = autocorrelation(r, lags)
    _, p = ljung_box(r, lags, rho)
    white = p > 1e-3

    offset = fit.value("offset")
    sw_data = find_swings(fit.t, fit.y, centre=offset, hysteresis=3 * noise)
    sw_fit = find_swings(fit.t, fit.fitted, centre=offset, hysteresis=3 * noise)
    swing_hz = sw_fit.damped_frequency / (2 * math.pi) if math.isfinite(sw_fit.damped_frequency) else float("nan")

    _, ru, dt = resample_uniform(fit.t, r)
    spec = np.abs(np.fft.rfft(ru - ru.mean())) ** 2
    freqs = np.fft.rfftfreq(ru.size, dt)
    line_hz, line_fraction, low_fraction = None, 0.0, 0.0
    total = float(spec[1:].sum())
    if total > 0 and spec.size > 8:
        k = int(np.argmax(spec[1:])) + 1
        band = spec[max(1, k - 3): k + 4].sum()
        line_hz, line_fraction = float(freqs[k]), float(band / total)
        if math.isfinite(swing_hz):
            low_fraction = float(spec[1:][freqs[1:] < 0.3 * swing_hz].sum() / total)

    amps = np.abs(sw_data.peak_values)
    good = (amps > 20 * noise) & sw_data.complete
    dec, dec_t = _decrement(sw_data.peak_values[good])
    law, errors = _envelope_law(sw_data.peak_times[good], amps[good])

    m = min(sw_data.peak_values.size, sw_fit.peak_values.size)
    fa_slope = fa_t = c_slope = c_t = asym = asym_t = 0.0
    if m >= 6 and sw_data.crossings.size >= 5 and sw_fit.crossings.size >= 5:
        mc = min(sw_data.crossings.size, sw_fit.crossings.size)
        # full periods (crossing i to i+2): half periods alternate when the
        # centre is off, which would hide an amplitude dependence
        w_data = 2 * math.pi / (sw_data.crossings[2:mc] - sw_data.crossings[:mc - 2])
        w_fit = 2 * math.pi / (sw_fit.crossings[2:mc] - sw_fit.crossings[:mc - 2])
        pk = np.abs(sw_data.peak_values)
        k2 = min(w_data.size, pk.size - 2)
        a_full = 0.5 * (pk[1:k2 + 1] + pk[2:k2 + 2])
        fa_slope, fa_t = _slope_t(a_full**2, (w_data - w_fit)[:k2])
        ok = sw_data.complete[:m] & sw_fit.complete[:m]
        pd, pf = sw_data.peak_values[:m], sw_fit.peak_values[:m]
        pair = ok[:-1] & ok[1:]
        mid = 0.5 * ((pd[:-1] + pd[1:]) - (pf[:-1] + pf[1:]))
        c_slope, c_t = _slope_t(sw_data.peak_times[1:m][pair], mid[pair])
        pd, pf = pd[ok], pf[ok]
        diff = np.abs(pd) - np.abs(pf)
        pos, neg = diff[pd > 0], diff[pd < 0]
        if pos.size >= 3 and neg.size >= 3:
            asym = float(pos.mean() - neg.mean())
            se = math.sqrt(pos.var(ddof=1) / pos.size + neg.var(ddof=1) / neg.size)
            asym_t = asym / se if se > 0 else 0.0
    structure_bic, envelope_bic = structure_test(fit, line_hz)
    return Diagnostics(
        residual_rms=rms, noise_floor=noise, rms_ratio=ratio, lag1=float(rho[1]), whiteness_p=p, white=white,
        swing_hz=swing_hz, line_hz=line_hz, line_fraction=line_fraction, low_frequency_fraction=low_fraction,
        envelope_law=law, envelope_errors=errors, stopped=stopped,
        freq_amp_slope=fa_slope, freq_amp_t=fa_t, centre_slope=c_slope, centre_t=c_t,
        asymmetry=asym, asymmetry_t=asym_t, decrement=dec, decrement_t=dec_t,
        structure_bic=structure_bic, envelope_bic=envelope_bic,
    )
