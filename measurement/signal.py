"""Signal facts read from the data itself: noise floor, outliers, swing window, swings.

These feed the starting values, the stopping rule of the discovery loop
(the noise floor) and the robustness real data needs (glitches, the part of
the record before the release and after the pendulum has stopped).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import comb

_MAD_TO_SIGMA = 1.482602218505602


def robust_std(x: np.ndarray) -> float:
    """σ from the median absolute deviation (insensitive to a few glitches)."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return float("nan")
    return float(_MAD_TO_SIGMA * np.median(np.abs(x - np.median(x))))


def regular_windows(t: np.ndarray | None, n: int, k: int) -> np.ndarray:
    """For each run of k+1 consecutive samples, whether it spans no gap.

    A gap (dropped frames, failed encoder reads) is a sample interval over
    1.5× the median; a difference or a local prediction across it measures
    the swing, not the noise.
    """
    if t is None or n <= k:
        return np.ones(max(n - k, 0), dtype=bool)
    dt = np.diff(np.asarray(t, dtype=float))
    bad = dt > 1.5 * float(np.median(dt))
    count = np.concatenate([[0], np.cumsum(bad)])
    return (count[k:] - count[:-k]) == 0 if k > 0 else np.ones(n, dtype=bool)


def noise_floor(angle: np.ndarray, exclude: np.ndarray | None = None, robust: bool = False,
                orders: range = range(2, 7), t: np.ndarray | None = None) -> float:
    """White-noise σ of a densely sampled smooth signal, rad.

    k-th differences remove a smooth signal (it contributes ≈ A·(ω·Δt)^k) and
    turn white noise of σ into noise of σ·sqrt(C(2k, k)). Each order gives an
    estimate that can only be biased upwards by the signal, so the smallest
    is kept. Quantisation counts as noise here: it is what the sensor cannot
    resolve.

    robust: use the median absolute deviation (immune to glitches, but
    itself quantised on encoder data: use it only to find glitches).
    exclude: indices of known glitches, masked out of the plain estimate.
    t: sample times (s); differences spanning a gap are left out.
    """
    y = np.asarray(angle, dtype=float)
    best = math.inf
    for k in orders:
        if y.size <= k + 10:
            break
        d = np.diff(y, n=k)
        keep = regular_windows(t, y.size, k)
        if exclude is not None and len(exclude):
            for i in np.asarray(exclude, dtype=int):
                keep[max(0, i - k): i + 1] = False
        d = d[keep]
        if d.size < 10:
            continue
        norm = math.sqrt(comb(2 * k, k))
        s = robust_std(d) / norm if robust else float(np.sqrt(np.mean(d**2))) / norm
        if s == 0.0 and robust:
            s = float(np.sqrt(np.mean(d**2))) / norm
        best = min(best, s)
    return float(best) if math.isfinite(best) else 0.0


def spike_candidates(angle: np.ndarray, sigma: float, threshold: float = 8.0,
                     t: np.ndarray | None = None) -> np.ndarray:
    """Indices of isolated glitches (tracking errors), found before any fit.

    Each sample is compared with the cubic through its two neighbours on
    each side, (−y[i−2] + 4y[i−1] + 4y[i+1] − y[i+2])/6, which follows a
    smooth swing; one glitch also disturbs its neighbours' predictions, so
    only the worst sample of a run is taken and the test repeated.
    """
    y = np.array(angle, dtype=float)
    n = y.size
    if n < 9 or sigma <= 0:
        return np.zeros(0, dtype=int)
    scale = sigma * math.sqrt(1.0 + 34.0 / 36.0)
    found: list[int] = []
    mask = np.zeros(n, dtype=bool)
    # the 5-sample prediction is only valid on evenly spaced neighbours
    mask[2:-2] = ~regular_windows(t, n, 4)
    for _ in range(max(1, n // 20)):
        pred = (-y[:-4] + 4 * y[1:-3] + 4 * y[3:-1] - y[4:]) / 6.0
        dev = np.abs(y[2:-2] - pred) / scale
        dev[mask[2:-2]] = 0.0
        i = int(np.argmax(dev))
        if dev[i] < threshold:
            break
        j = i + 2
        found.append(j)
        mask[j] = True
        # replace by the prediction so that the next pass sees a clean neighbourhood
        y[j] = pred[i]
    return np.array(sorted(found), dtype=int)


@dataclass(frozen=True)
class Swings:
    """Half-swing facts of a trace around a centre line.

    crossings: times of the zero crossings of angle − centre, s.
    peak_times/peak_values: extremum times (s) and signed excursions (rad)
    of every lobe; lobe j lies before crossing j.
    complete: whether lobe j's extremum is a real turning point: not the
    record's first sample, and not the last lobe, cut off by the record's end.
    """

    centre: float
    crossings: np.ndarray
    peak_times: np.ndarray
    peak_values: np.ndarray
    complete: np.ndarray

    @property
    def count(self) -> float:
        """Full swings (periods) observed."""
        return max(0, self.crossings.size - 1) / 2.0

    @property
    def damped_frequency(self) -> float:
        """Median ω_d from the half periods, rad/s (nan with < 2 crossings)."""
        if self.crossings.size < 2:
            return float("nan")
        return float(math.pi / np.median(np.diff(self.crossings)))


def find_swings(t: np.ndarray, angle: np.ndarray, centre: float | None = None, hysteresis: float = 0.0) -> Swings:
    """Zero crossings and extrema of a swing about ``centre`` (default: median).

    hysteresis: a crossing counts only after the signal has gone beyond
    ±hysteresis (rad) on the other side, so that noise around a stopped
    pendulum does not count as swings.
    """
    y = np.asarray(angle, dtype=float)
    t = np.asarray(t, dtype=float)
    c = float(np.median(y)) if centre is None else float(centre)
    z = y - c
    crossings: list[float] = []
    peaks_t: list[float] = []
    peaks_v: list[float] = []
    state = 0  # sign of the current lobe once it passed the hysteresis
    lobe_i = -1
    for i in range(z.size):
        zi = z[i]
        if state >= 0 and zi < -hysteresis:
            if state == 1:
                crossings.append(_crossing_time(t, z, i))
                peaks_t.append(t[lobe_i])
                peaks_v.append(z[lobe_i])
            state, lobe_i = -1, i
        elif state <= 0 and zi > hysteresis:
            if state == -1:
                crossings.append(_crossing_time(t, z, i))
                peaks_t.append(t[lobe_i])
                peaks_v.append(z[lobe_i])
            state, lobe_i = 1, i
        elif state != 0 and state * zi > state * z[lobe_i]:
            lobe_i = i
    if state != 0 and lobe_i >= 0:
        peaks_t.append(t[lobe_i])
        peaks_v.append(z[lobe_i])
    complete = np.ones(len(peaks_v), dtype=bool)
    if complete.size:
        complete[-1] = False
        # the first lobe's extremum at the very first sample may be mid-swing
        complete[0] = peaks_t[0] > t[0]
    return Swings(c, np.asarray(crossings), np.asarray(peaks_t), np.asarray(peaks_v), complete)


def _crossing_time(t: np.ndarray, z: np.ndarray, i: int) -> float:
    # walk back to the sign change just before i and interpolate linearly
    j = i
    while j > 0 and np.sign(z[j - 1]) == np.sign(z[i]):
        j -= 1
    if j == 0:
        return float(t[i])
    z0, z1 = z[j - 1], z[j]
    frac = z0 / (z0 - z1) if z0 != z1 else 0.5
    return float(t[j - 1] + frac * (t[j] - t[j - 1]))


@dataclass(frozen=True)
class SwingWindow:
    """Index range [start, stop) of the free swing, and why it was cut there."""

    start: int
    stop: int
    release_detected: bool
    stop_detected: bool
    #: the pendulum came to rest (a flat tail at the noise level), as only
    #: dry friction makes it; a swing that merely decayed into the noise is not
    stuck: bool = False


def swing_window(t: np.ndarray, angle: np.ndarray, sigma: float) -> SwingWindow:
    """Where the pendulum swings: after the release, until it has stopped.

    Release: a pre-trigger hold is a run of samples at the start that stay
    within the noise of the first ones; the fit starts at the last held
    sample (θ' ≈ 0 there, which the free initial state absorbs).
    Stop: the last swing whose excursion is still ≥ 10σ (or the pendulum
    stuck by friction); the half-swing after it is kept.
    """
    y = np.asarray(angle, dtype=float)
    n = y.size
    tol = max(6.0 * sigma, 1e-12)
    head = y[: max(5, min(n // 50, 50))]
    hold = float(np.median(head))
    moved = np.flatnonzero(np.abs(y - hold) > tol)
    start = 0
    release = False
    if moved.size and moved[0] > 3:
        start = int(moved[0]) - 1
        release = True
    # end of motion: the last sample that differs from the final resting value
    tail = y[-max(5, min(n // 50, 50)):]
    rest = float(np.median(tail))
    moving = np.flatnonzero(np.abs(y - rest) > tol)
    stop = n
    stopped = stuck = False
    if moving.size and moving[-1] < n - 4:
        stop = min(n, int(moving[-1]) + 2)
        stopped = True
        tail_after = y[stop:]
        stuck = tail_after.size >= 20 and float(np.std(tail_after)) <= 1.5 * sigma
    # swings decayed into the noise carry no information but cost time
    if stop - start > 20:
        sw = find_swings(t[start:stop], y[start:stop], centre=rest, hysteresis=3 * sigma)
        big = np.flatnonzero(np.abs(sw.peak_values) >= 10.0 * sigma)
        if big.size and big[-1] + 1 < sw.peak_times.size:
            t_cut = sw.peak_times[big[-1] + 1]
            cut = int(np.searchsorted(t, t_cut, side="right"))
            if cut < stop:
                stop, stopped = cut, True
    return SwingWindow(start=start, stop=max(stop, start + 1), release_detected=release, stop_detected=stopped,
                       stuck=stuck)
