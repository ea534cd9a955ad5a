"""The measurement noise model: an autoregressive process fitted to the residual.

Camera and encoder noise is rarely white: tracking wobbles over a few
frames, quantisation is correlated where the swing is slow, vibration adds
colour. Counting such a residual as n independent samples overstates the
information (χ², BIC and σ too optimistic: effects "found" in the noise's
colour, J_std too small). The residual r is therefore modelled as an AR(p)
process, A(q)·r = e with e white of variance σ_e², the order p chosen by the
data (BIC over 0 … ``MAX_ORDER``). The Gaussian log-likelihood of the record
is then −n/2·log σ_e² + const (the conditional likelihood, see Box, Jenkins
and Reinsel, "Time Series Analysis: Forecasting and Control", ch. 7), and
the parameters' covariance is the sandwich (JᵀJ)⁻¹·JᵀΣJ·(JᵀJ)⁻¹ with Σ the
AR process's covariance: the least-squares estimate stays efficient for
smooth, swing-like regressors (Grenander's theorem) while its uncertainty
follows the noise actually seen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import gammaincc

from .signal import all_pole_filter, fir_filter

#: highest AR order tried (a coloured camera or encoder noise needs a few)
MAX_ORDER = 12


def lagged_products(rc: np.ndarray, max_lag: int) -> np.ndarray:
    """Σ_i rc[i]·rc[i+k] for k = 0..max_lag (the biased autocovariance times n).

    The few lags the noise model and the whiteness test need are direct dot
    products; many lags (of a long one) go by FFT, zero-padded so that the
    circular correlation equals the linear one.
    """
    n = rc.size
    max_lag = min(max_lag, n - 1)
    if max_lag <= 32:
        return np.array([float(rc[: n - k] @ rc[k:]) for k in range(max_lag + 1)])
    nfft = 1 << (n + max_lag).bit_length()
    f = np.fft.rfft(rc, nfft)
    return np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1]


def autocorrelation(r: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocorrelation ρ(0..max_lag) of a residual (biased estimator)."""
    r = np.asarray(r, dtype=float) - np.mean(r)
    ac = np.zeros(max_lag + 1)
    ac[: min(max_lag, r.size - 1) + 1] = lagged_products(r, max_lag)
    return ac / ac[0] if ac[0] > 0 else np.zeros(max_lag + 1)


def ljung_box(r: np.ndarray, lags: int, rho: np.ndarray | None = None) -> tuple[float, float]:
    """Ljung–Box statistic Q and its p-value (χ² with ``lags`` degrees of freedom) for whiteness.

    rho: r's ``autocorrelation`` to at least ``lags``, when the caller has it already.
    """
    n = r.size
    rho = autocorrelation(r, lags) if rho is None else rho[: lags + 1]
    q = n * (n + 2) * float(np.sum(rho[1:] ** 2 / (n - np.arange(1, lags + 1))))
    # the χ² survival function is the regularised upper incomplete gamma function
    return q, float(gammaincc(lags / 2.0, q / 2.0))


@dataclass(frozen=True)
class NoiseModel:
    """AR(p) noise: r[i] + a1·r[i−1] + … + ap·r[i−p] = e[i], e white with variance ``innovation_var`` (rad²)."""

    a: np.ndarray  # (1, a1, …, ap)
    innovation_var: float
    variance: float  # of r itself, rad²

    @property
    def order(self) -> int:
        return int(self.a.size - 1)

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """A(q)·x along axis 0 (the first p rows are left out: they have no full past)."""
        if self.order == 0:
            return x
        return fir_filter(self.a, x)

    def colour_t(self, x: np.ndarray) -> np.ndarray:
        """A(q)⁻ᵀ·x (anticausal inverse filter) along axis 0: Σ = σ_e²·A⁻¹A⁻ᵀ, so xᵀΣx = σ_e²·‖A⁻ᵀx‖²."""
        if self.order == 0:
            return x
        return all_pole_filter(self.a, x[::-1])[::-1]


def levinson(acov: np.ndarray, order: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Yule–Walker AR fits of orders 0..order (Levinson–Durbin): coefficient vectors and innovation variances."""
    a = np.array([1.0])
    err = float(acov[0])
    coefs, errs = [a.copy()], [err]
    for k in range(1, order + 1):
        if err <= 0:
            break
        acc = float(np.dot(a, acov[k:0:-1]))
        refl = -acc / err
        a = np.concatenate([a, [0.0]])
        a = a + refl * a[::-1]
        err *= 1.0 - refl * refl
        coefs.append(a.copy())
        errs.append(err)
    return coefs, np.asarray(errs)


def fit_noise(r: np.ndarray, max_order: int = MAX_ORDER) -> NoiseModel:
    """AR noise model of residual r (rad), order by BIC (0 when the residual is white)."""
    r = np.asarray(r, dtype=float)
    n = r.size
    max_order = int(min(max_order, max(0, n // 50)))
    rc = r - r.mean()
    acov = lagged_products(rc, max_order) / n
    var = float(np.mean(r * r))
    if acov[0] <= 0:
        return NoiseModel(np.array([1.0]), var, var)
    coefs, errs = levinson(acov, max_order)
    # innovation variance about the residual's own mean is acov·(err/acov0); keep the mean's share
    scale = var / acov[0]
    bic = [n * math.log(max(e * scale, 1e-300)) + p * math.log(n) for p, e in enumerate(errs)]
    p = int(np.argmin(bic))
    return NoiseModel(coefs[p], float(errs[p] * scale), var)
