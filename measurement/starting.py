"""Starting values of a model's fit, by equation error: θ, θ', θ'' from a Savitzky–Golay filter of
the samples, then a bounded linear regression −θ'' = ω_n²·r(θ) + Σ p·φ(θ, θ') (every effect is
linear in its normalised parameters). Falls back to zero crossings and each effect's own fallback
when the regression is unusable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear

from .errors import IdentificationError
from .model import STATE_PARAMS, Model
from .restoring import restoring_column
from .signal import Swings, find_swings, periodogram, resample_uniform, savitzky_golay

__all__ = ["Smoothed", "initial_guess", "smooth"]


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
    if model.measures == "rate":
        centre, angle, rate, accel, sw = _from_rate(smoothed)
    else:
        centre, sw = smoothed.centre, smoothed.swings
        angle, rate, accel = smoothed.ys - centre, smoothed.yd, smoothed.ydd
    reg = _regression(model, smoothed, angle, rate, accel)
    amplitude = float(np.max(np.abs(angle)))
    omega_n, values = _effect_starts(model, reg, smoothed.omega_d, sw, amplitude, sigma)
    x = model.vector((float(angle[0]), float(rate[0]), omega_n), values, centre)
    scales = _scales(model, t, reg, omega_n, amplitude)
    lo_b, hi_b = model.bounds()
    return np.clip(x, lo_b, hi_b), scales


@dataclass(frozen=True)
class _Regression:
    """The equation-error regression −θ'' = ω_n²·r(θ) + Σ p·φ(θ, θ'): its restoring column r, its
    columns' rms and its coefficients (ω_n², then each dynamic effect's; None when unusable)."""

    restoring: np.ndarray
    col_rms: np.ndarray
    coef: np.ndarray | None


def _regression(model: Model, smoothed: Smoothed, angle: np.ndarray, rate: np.ndarray,
                accel: np.ndarray) -> _Regression:
    window = smoothed.window
    rows = np.arange(angle.size)[slice(window, max(window + 1, angle.size - window))]
    regress = True
    if smoothed.supported is not None:
        kept = rows[smoothed.supported[rows]]
        # too few rows between the gaps: ω_n starts at the swings' ω_d instead of a regression
        regress = kept.size >= 2 * window + len(model.dynamic) + 3
        rows = kept if regress else rows
    xs, vs, acc = angle[rows], rate[rows], accel[rows]
    restoring = restoring_column(model.rig.kind, xs, vs, acc, model.rig.geometry)
    A = np.hstack([restoring[:, None]] + [e.basis(xs, vs) for e in model.dynamic])
    lo_b, _ = model.bounds()
    lo = np.concatenate([[0.0], lo_b[len(STATE_PARAMS):model.n_dynamic]])
    hi = np.full(lo.size, np.inf)
    # scales: the parameter value whose term is as large as the restoring one
    col_rms = np.sqrt(np.mean(A**2, axis=0))
    col_rms[col_rms == 0] = 1.0
    if not regress:
        return _Regression(restoring, col_rms, None)
    try:
        sol = lsq_linear(A / col_rms, -acc, bounds=(lo, hi), method="bvls")
    except (ValueError, np.linalg.LinAlgError):
        return _Regression(restoring, col_rms, None)
    coef = sol.x / col_rms
    ok = bool(sol.success and coef[0] > 0 and np.all(np.isfinite(coef)))
    if ok:
        # the regression is biased by noise on θ''; trust it only near ω_d (closer with gaps,
        # where fewer rows hold it and the periodogram's ω_d is the sharper figure)
        wd = smoothed.omega_d
        near = (0.7, 1.4) if smoothed.supported is None else (0.9, 1.15)
        ok = near[0] * wd < math.sqrt(coef[0]) < near[1] * wd
    return _Regression(restoring, col_rms, coef if ok else None)


def _effect_starts(model: Model, reg: _Regression, wd: float, sw: Swings, amplitude: float,
                   sigma: float) -> tuple[float, dict[str, list[float]]]:
    """(ω_n, each dynamic effect's starting values): the regression's, else the swings' ω_d and each effect's fallback."""
    values: dict[str, list[float]] = {}
    if reg.coef is not None:
        omega_n = math.sqrt(reg.coef[0])
        i = 1
        for e in model.dynamic:
            values[e.name] = list(reg.coef[i:i + len(e.parameters)])
            i += len(e.parameters)
    else:
        omega_n = wd
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
    return omega_n, values


def _scales(model: Model, t: np.ndarray, reg: _Regression, omega_n: float, amplitude: float) -> np.ndarray:
    """Each parameter's typical size: the value whose term is as large as the swing's own."""
    restoring_rms = omega_n**2 * float(np.sqrt(np.mean(reg.restoring**2)))
    scales = np.empty(model.size)
    scales[:3] = [max(amplitude, 1e-6), max(amplitude * omega_n, 1e-6), omega_n]
    scales[3:model.n_dynamic] = restoring_rms / reg.col_rms[1:]
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
    return scales


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
