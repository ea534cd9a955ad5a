"""Signal facts read from the data itself: noise floor, outliers, swing window, swings.

These feed the starting values, the stopping rule of the discovery loop
(the noise floor) and the robustness real data needs (glitches, the part of
the record before the release and after the pendulum has stopped).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_MAD_TO_SIGMA = 1.482602218505602


def robust_std(x: np.ndarray) -> float:
    """σ from the median absolute deviation (insensitive to a few glitches)."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return float("nan")
    return float(_MAD_TO_SIGMA * np.median(np.abs(x - np.median(x))))


#: an even grid has at most this many points per sample: a gap in the record costs no more than its samples
MAX_GRID_PER_SAMPLE = 4


def resample_uniform(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(t, y, dt) on an even grid at the median interval dt (s); as given when already even to 1 %.

    For the tools that need even spacing (Savitzky–Golay, FFT); the fit itself
    always uses the true timestamps. A record whose span would need more than
    ``MAX_GRID_PER_SAMPLE`` grid points per sample (a long gap) gets the coarser
    interval that fits in them: the cost is bounded by the samples, not the span.
    """
    dt = float(np.median(np.diff(t)))
    if np.max(np.abs(np.diff(t) - dt)) <= 0.01 * dt:
        return t, y, dt
    dt = max(dt, float(t[-1] - t[0]) / (MAX_GRID_PER_SAMPLE * len(t)))
    tu = np.arange(t[0], t[-1], dt)
    return tu, np.interp(tu, t, y), dt


@dataclass(frozen=True)
class Periodogram:
    """A least-squares periodogram at the true sample times (Lomb and Scargle's idea).

    w: angular frequencies on a grid of 1/span (a peak is 2π/span wide), rad/s; power: each one's
    explained sum of squares by a sinusoid plus a constant, rad²; span: the record's, s. Unlike zero
    crossings, which a record of bursts between silences places wherever the line across a silence
    meets the centre, it weighs every sample where it was taken.
    """

    w: np.ndarray
    power: np.ndarray
    span: float

    def _refined(self, k: int) -> float:
        """Grid point k moved to the vertex of the parabola through it and its neighbours, rad/s."""
        w, power = self.w, self.power
        if 0 < k < w.size - 1:
            a, b, c = power[k - 1], power[k], power[k + 1]
            den = a - 2 * b + c
            if den < 0:
                return float(w[k] + 0.5 * (a - c) / den * (w[1] - w[0]))
        return float(w[k])

    def frequency(self, lo: float, hi: float) -> float:
        """The angular frequency in [lo, hi] (rad/s) whose sinusoid fits best; nan when none is on the grid."""
        inside = np.flatnonzero((self.w >= lo) & (self.w <= hi))
        if not inside.size:
            return float("nan")
        return self._refined(int(inside[np.argmax(self.power[inside])]))

    def peaks(self, comparable: float = 0.5) -> list[float]:
        """The peaks at least ``comparable`` × the highest's power, tallest first, each more than a peak's
        width (2π/span) from every taller one, rad/s.

        On a record of bursts between silences the sampling has its own quasi-period: the swing's
        frequency shifted by it explains the samples nearly as well (an alias), and only a fit at
        each tells which one the swing is.
        """
        power = self.power
        if power.size < 3:
            return []
        top = float(np.max(power))
        local = np.flatnonzero((power[1:-1] >= power[:-2]) & (power[1:-1] >= power[2:])) + 1
        out: list[float] = []
        for k in sorted(local, key=lambda k: -power[k]):
            if power[k] < comparable * top:
                break
            wk = self._refined(int(k))
            if all(abs(wk - o) > 2 * math.pi / self.span for o in out):
                out.append(wk)
        return out


def periodogram(t: np.ndarray, y: np.ndarray, lo: float, hi: float) -> Periodogram:
    """The least-squares periodogram of (t in s, y in rad) over [lo, hi] rad/s (empty for a bad band or span)."""
    t = np.asarray(t, dtype=float) - float(t[0])
    y = np.asarray(y, dtype=float) - float(np.mean(y))
    span = float(t[-1])
    if not (span > 0 and hi > lo > 0):
        return Periodogram(np.zeros(0), np.zeros(0), span)
    w = np.arange(lo, hi + 1.0 / span, 1.0 / span)
    power = np.empty(w.size)
    for i, wi in enumerate(w):
        A = np.column_stack([np.cos(wi * t), np.sin(wi * t), np.ones_like(t)])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        power[i] = float(y @ (A @ coef))  # the explained sum of squares
    return Periodogram(w, power, span)


def loo_deviations(t: np.ndarray | None, y: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-out deviations of each sample from its neighbours, at the true times.

    For i in [d, n − d): y[i] − P(t[i]), with P the polynomial of degree 2d − 1
    through the d samples on each side, divided by sqrt(1 + Σw²) (w: the
    Lagrange weights), so that white noise of σ gives deviations of σ while a
    smooth swing leaves only ≈ A·(ω·Δt)^(2d). Exact for uneven timestamps,
    where plain differences leak θ'·(timestamp jitter).
    Returns (indices, normalised deviations).
    """
    y = np.asarray(y, dtype=float)
    n = y.size
    if n < 2 * d + 1:
        return np.zeros(0, dtype=int), np.zeros(0)
    tt = np.arange(n, dtype=float) if t is None else np.asarray(t, dtype=float)
    idx = np.arange(d, n - d)
    offsets = [o for o in range(-d, d + 1) if o != 0]
    # one array per neighbour, whole-array operations written into buffers
    m = n - 2 * d
    nodes = [tt[d + o:n - d + o] - tt[d:n - d] for o in offsets]
    f = np.empty(m)
    pred = np.zeros(m)
    sum_w2 = np.zeros(m)
    for j, o in enumerate(offsets):
        w = np.ones(m)
        for k in range(len(offsets)):
            if k != j:
                np.subtract(nodes[j], nodes[k], out=f)
                np.divide(nodes[k], f, out=f)
                np.negative(f, out=f)
                w *= f  # the Lagrange weight of neighbour j
        pred += w * y[d + o:n - d + o]
        sum_w2 += w * w
    dev = y[d:n - d] - pred
    return idx, dev / np.sqrt(1.0 + sum_w2)


Deviations = dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]


def deviation_table(angle: np.ndarray, t: np.ndarray | None = None, orders: tuple[int, ...] = (1, 2, 3)) -> Deviations:
    """d → (indices, ``loo_deviations``, whether each window is gap-free) for each d in ``orders``.

    Computed once for a record and handed to ``noise_floor`` and
    ``spike_candidates`` (``table=``), which otherwise each compute the same.
    """
    y = np.asarray(angle, dtype=float)
    bad = None
    if t is not None:
        dt = np.diff(np.asarray(t, dtype=float))
        bad = np.concatenate([[0], np.cumsum(dt > 3.0 * float(np.median(dt)))])
    out: Deviations = {}
    for d in orders:
        idx, dev = loo_deviations(t, y, d)
        out[d] = (idx, dev, np.ones(idx.size, dtype=bool) if bad is None else (bad[idx + d] - bad[idx - d]) == 0)
    return out


def noise_floor(angle: np.ndarray, exclude: np.ndarray | None = None, robust: bool = False,
                t: np.ndarray | None = None, orders: tuple[int, ...] = (1, 2, 3),
                table: Deviations | None = None) -> float:
    """White-noise σ of a densely sampled smooth signal, rad.

    Each sample is predicted from its neighbours (``loo_deviations``, with d
    neighbours a side for every d in ``orders``); the smooth swing cancels and
    the noise remains. Each order gives an estimate that the signal can only
    bias upwards, so the smallest is kept. Quantisation counts as noise here:
    it is what the sensor cannot resolve.

    robust: use the median absolute deviation (immune to glitches, but
    itself quantised on encoder data: use it only to find glitches).
    exclude: indices of known glitches, left out with their neighbourhoods.
    t: sample times (s), for uneven sampling and gaps.
    table: ``deviation_table(angle, t, orders)`` when the caller has it.
    """
    y = np.asarray(angle, dtype=float)
    if table is None:
        table = deviation_table(y, t, orders)
    best = math.inf
    for d in orders:
        idx, dev, keep = table[d]
        if idx.size < 10:
            continue
        if exclude is not None and len(exclude):
            near = np.zeros(y.size, dtype=bool)
            for i in np.asarray(exclude, dtype=int):
                near[max(0, i - d): i + d + 1] = True
            keep = keep & ~near[idx]
        dev = dev[keep]
        if dev.size < 10:
            continue
        plain = float(np.sqrt(np.mean(dev**2)))
        est = robust_std(dev) if robust else plain
        best = min(best, est if est > 0 else plain)
    return float(best) if math.isfinite(best) else 0.0


def spike_candidates(angle: np.ndarray, sigma: float, threshold: float = 8.0,
                     t: np.ndarray | None = None, table: Deviations | None = None) -> np.ndarray:
    """Indices of isolated glitches (tracking errors), found before any fit.

    Each sample is compared with the cubic through its two neighbours on
    each side (``loo_deviations`` with d = 2), which follows a smooth swing;
    one glitch also disturbs its neighbours' predictions, so only the worst
    sample of a run is taken, replaced by its prediction, and the test
    repeated. table: ``deviation_table(angle, t)`` when the caller has it.
    """
    y = np.array(angle, dtype=float)
    n = y.size
    if n < 9 or sigma <= 0:
        return np.zeros(0, dtype=int)
    found: list[int] = []
    skip = np.zeros(n, dtype=bool)
    idx, dev, gap_free = table[2] if table is not None and 2 in table else deviation_table(y, t, (2,))[2]
    skip[idx[~gap_free]] = True  # no prediction across a gap
    dev = dev.copy()  # updated below; the table's stays that of the record

    def replace(j: int, deviation: float) -> None:
        found.append(j)
        skip[j] = True
        # replace by the prediction so that the next pass sees a clean neighbourhood
        y[j] -= deviation
        # only the samples with j among their two neighbours a side see the change (idx[p] = p + 2)
        lo, hi = max(0, j - 4), min(n, j + 5)
        near, near_dev = loo_deviations(None if t is None else t[lo:hi], y[lo:hi], 2)
        dev[near + lo - 2] = near_dev

    # The two samples at each end have no neighbours on one side: each is compared with the
    # parabola through the three samples inward of it, the inner one first, before the interior
    # (a tracker that starts on the wrong blob gives a record whose first samples jump by a
    # large angle, and the interior test would then blame their good neighbours).
    typical = math.inf if t is None else float(np.median(np.diff(t)))  # sampling interval, s (no times: no gaps)
    for j in (1, 0, n - 2, n - 1):
        step = 1 if j < n // 2 else -1
        nodes = [j + step, j + 2 * step, j + 3 * step]
        if t is not None and np.max(np.abs(np.diff(t[[j] + nodes]))) > 3 * typical:
            continue  # no extrapolation across a gap (the window's gap rule judges what lies beyond)
        d = _lagrange_deviation(t, y, j, nodes)
        if abs(d) / (_EDGE_GAIN * sigma) >= threshold:
            replace(j, d)
    for _ in range(max(1, n // 20)):
        score = np.abs(dev) / sigma
        score[skip[idx]] = 0.0
        k = int(np.argmax(score))
        if score[k] < threshold:
            break
        j = int(idx[k])
        replace(j, _raw_deviation(t, y, j))
    return np.array(sorted(found), dtype=int)


#: noise gain of the one-step extrapolation by a parabola through three equally spaced samples (√(3² + 3² + 1²))
_EDGE_GAIN = math.sqrt(19.0)


def _lagrange_deviation(t: np.ndarray | None, y: np.ndarray, j: int, nodes: list[int]) -> float:
    """y[j] minus the polynomial through y at ``nodes`` (Lagrange form), rad."""
    tt = np.arange(y.size, dtype=float) if t is None else np.asarray(t, dtype=float)
    pred = 0.0
    for a in nodes:
        w = 1.0
        for b in nodes:
            if b != a:
                w *= (tt[j] - tt[b]) / (tt[a] - tt[b])
        pred += w * y[a]
    return float(y[j] - pred)


def _raw_deviation(t: np.ndarray | None, y: np.ndarray, j: int) -> float:
    """y[j] minus the cubic through its two neighbours on each side (not normalised)."""
    return _lagrange_deviation(t, y, j, [j - 2, j - 1, j + 1, j + 2])


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
        """Median ω_d from the full periods, rad/s (from the half periods with 2 crossings; nan with fewer).

        A full period runs from a crossing to the next but one: it does not depend on where
        the centre line is, while a half period does (a centre off by δ lengthens every other
        half period and shortens the rest, and a sparse record's median then picks one kind).
        """
        c = self.crossings
        if c.size < 2:
            return float("nan")
        if c.size < 3:
            return float(math.pi / (c[1] - c[0]))
        return float(2 * math.pi / np.median(c[2:] - c[:-2]))


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
    # Vectorised hysteresis: a sample beyond ±hysteresis sets the lobe's sign,
    # one inside the band keeps the current lobe; a lobe starts where the sign
    # of the samples beyond the band changes, and its extremum is its first
    # sample of largest excursion.
    side = np.where(z > hysteresis, 1, np.where(z < -hysteresis, -1, 0))
    beyond = np.flatnonzero(side)
    crossings = peaks_t = peaks_v = np.zeros(0)
    if beyond.size:
        sb = side[beyond]
        starts = beyond[np.concatenate(([True], sb[1:] != sb[:-1]))]
        signs = side[starts]
        lengths = np.diff(np.append(starts, z.size))
        excursion = np.repeat(signs, lengths) * z[starts[0]:]
        best = np.maximum.reduceat(excursion, starts - starts[0])
        at_best = np.flatnonzero(excursion == np.repeat(best, lengths)) + starts[0]
        lobe = at_best[np.searchsorted(at_best, starts)]
        crossings = _crossing_times(t, z, starts[1:])
        peaks_t = t[lobe]
        peaks_v = z[lobe]
    complete = np.ones(peaks_v.size, dtype=bool)
    if complete.size:
        complete[-1] = False
        # the first lobe's extremum at the very first sample may be mid-swing
        complete[0] = peaks_t[0] > t[0]
    return Swings(c, crossings, peaks_t, peaks_v, complete)


def _crossing_times(t: np.ndarray, z: np.ndarray, at: np.ndarray) -> np.ndarray:
    """For each index i in ``at``: walk back to the sign change just before i and interpolate linearly."""
    sg = np.sign(z)
    # where each run of samples of one sign begins; i's run begins at j, so the
    # sign changes between j − 1 and j (j = 0: no change before i)
    runs = np.concatenate(([0], np.flatnonzero(sg[1:] != sg[:-1]) + 1))
    j = runs[np.searchsorted(runs, at, side="right") - 1]
    jj = np.maximum(j, 1)
    z0, z1 = z[jj - 1], z[jj]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(z0 != z1, z0 / (z0 - z1), 0.5)
    return np.where(j == 0, t[at], t[jj - 1] + frac * (t[jj] - t[jj - 1]))


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
    # the hold's level from its first five samples only: a short hold (a link that stalled at the
    # start delivers few of its samples) must not have its level pulled by the release after it;
    # a hold is then at least those five samples
    held = 5
    hold = float(np.median(y[:held]))
    moved = np.flatnonzero(np.abs(y - hold) > tol)
    start = 0
    release = False
    if moved.size and moved[0] >= held:
        start = int(moved[0]) - 1
        release = True
    else:
        # a hold shorter than five samples (even one) counts when a silence of the link ends it
        left = np.flatnonzero(np.abs(y - y[0]) > tol)
        if left.size and left[0] >= 1 and _silence_before(t, int(left[0])):
            start = int(left[0]) - 1
            release = True
    if release and _silence_before(t, start + 1):
        # the release fell somewhere in a silence: the last held sample is not where the free swing
        # began (a free swing through it does not exist), the first moving one is the first known
        start += 1
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


#: a gap between two samples longer than this many typical sampling steps is a silence of the link
SILENCE_STEPS = 5.0


def _silence_before(t: np.ndarray, i: int) -> bool:
    """Whether samples i − 1 and i of ``t`` (s) are a silence apart (no samples where there should be some)."""
    if not 0 < i < t.size or t.size < 3:
        return False
    return bool(t[i] - t[i - 1] > SILENCE_STEPS * float(np.median(np.diff(t))))


def savitzky_golay(y: np.ndarray, window: int, order: int, deriv: int = 0, delta: float = 1.0,
                   ends: str = "fit") -> np.ndarray:
    """The ``deriv``-th derivative of y (per delta, s) by a least-squares polynomial of ``order`` over a
    centred odd ``window`` of samples (Savitzky and Golay, "Smoothing and differentiation of data by
    simplified least squares procedures", 1964).

    ends: ``"fit"`` evaluates the polynomial fitted to the first and last window at the samples less than
    half a window from the ends; ``"zero"`` treats the samples beyond the ends as zeros. A few lines of
    numpy instead of ``scipy.signal``, whose import alone costs a cold-started command most of a second.
    """
    y = np.asarray(y, dtype=float)
    half = window // 2
    # offsets in half windows keep the Vandermonde matrix well conditioned; row `deriv` of its
    # pseudo-inverse maps a window of samples to that coefficient of the fitted polynomial
    offsets = np.arange(-half, half + 1, dtype=float) / max(half, 1)
    weights = np.linalg.pinv(np.vander(offsets, order + 1, increasing=True))[deriv]
    weights *= math.factorial(deriv) / (delta * max(half, 1)) ** deriv
    out = np.correlate(np.concatenate((np.zeros(half), y, np.zeros(half))), weights, mode="valid")
    if ends == "fit" and y.size >= window:
        at = np.arange(window, dtype=float)
        for sl, where in ((slice(0, window), slice(0, half)), (slice(y.size - window, y.size), slice(window - half, window))):
            poly = np.polynomial.polynomial.Polynomial.fit(at, y[sl], order, domain=[0.0, 1.0], window=[0.0, 1.0])
            out[sl][where] = poly.deriv(deriv)(at[where]) / delta ** deriv
    return out


def fir_filter(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Σ_k a[k]·x[i−k] along axis 0, for i ≥ len(a) − 1 (the rows with a full past)."""
    p = a.size - 1
    n = x.shape[0]
    out = a[0] * x[p:]
    for k in range(1, p + 1):
        out = out + a[k] * x[p - k:n - k]
    return out


def all_pole_filter(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """y with Σ_k a[k]·y[i−k] = x[i] along axis 0 (y before the start taken as zero; a[0] = 1): the
    inverse of ``fir_filter``, solved as a banded lower-triangular system."""
    from scipy.linalg import solve_banded  # already loaded by the diagnostics' Cholesky solve

    p = a.size - 1
    bands = np.repeat(np.asarray(a, dtype=float)[:, None], x.shape[0], axis=1)
    return solve_banded((p, 0), bands, x, check_finite=False)
