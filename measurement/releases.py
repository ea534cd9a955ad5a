"""Releases in a log: where each free swing starts, and which stretches of a log are swings at all.

A phone or a lab logger records what the hand did as well as what the pendulum did: it is held, let
go, swings, comes to rest, is picked up and let go again. A log is split into sections at its
events (phyphox's START/PAUSE: the clock stops while paused, so the samples either side of a pause
join without a gap), at gaps in its clock and at rests (the reading within the noise for two swing
periods); in each section the free swing starts at the turning point before its largest excursion
(a pendulum let go from rest swings widest first: the first excursion near the largest), so that the hold and the hand's transient before
it are cut. A section whose swing is not a regular decaying oscillation (handling, a shake) holds no
release. Pure computation on arrays: the readers of ``service.sources`` call it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .signal import find_swings, noise_floor

#: a rest: the swing's envelope within this many noise σ of its centre ...
REST_SIGMA = 6.0
#: ... for at least this many swing periods
REST_PERIODS = 2.0
#: a swing counts from this many noise σ (as the identification's window does)
SWING_SIGMA = 10.0
#: what a section begins with when the swing rested before it
REST = "a rest"
#: a release has at least this many half-swings above SWING_SIGMA after its start
MIN_HALF_SWINGS = 6
#: the half-periods of a free swing scatter less than this, relative (handling scatters far more)
MAX_HALF_PERIOD_SPREAD = 0.25
#: the release's first excursion is at least this share of the section's largest (a swing decays from its release)
RELEASE_SHARE = 0.8
#: a gap in the clock longer than this many sampling steps and than GAP_SECONDS splits a log
GAP_STEPS = 50.0
GAP_SECONDS = 2.0


@dataclass(frozen=True)
class Release:
    """One free swing found in a log.

    number: from 1, in time order. start / stop: s, the free swing's first sample and the section's
    last. section_start: s, where its section began (start − section_start was cut: the hold and the
    hand's transient). begins: what began the section ("the log's start", "an event START", "a gap
    of 3.2 s", "a rest"). amplitude: the largest excursion from the centre, in the reading's unit.
    i_start / i_stop: sample indices of start and one past stop.
    """

    number: int
    start: float
    stop: float
    section_start: float
    begins: str
    amplitude: float
    i_start: int
    i_stop: int

    @property
    def cut(self) -> float:
        """s cut before the free swing (the hold and the hand's transient)."""
        return self.start - self.section_start


@dataclass(frozen=True)
class Skipped:
    """A section with no release in it: start, stop (s) and why."""

    start: float
    stop: float
    why: str


@dataclass(frozen=True)
class Releases:
    """The releases of a log and the sections that held none; noise: the reading's noise floor."""

    found: tuple[Release, ...]
    skipped: tuple[Skipped, ...]
    noise: float


def _swing_period(t: np.ndarray, y: np.ndarray, noise: float) -> float:
    """The typical swing period of the log, s (NaN: no swing): twice the median time between crossings."""
    sw = find_swings(t, y, hysteresis=SWING_SIGMA * noise)
    if sw.crossings.size < 3:
        return math.nan
    return 2.0 * float(np.median(np.diff(sw.crossings)))


def _width(t: np.ndarray, period: float) -> int:
    """Samples in one period (odd, at least 3)."""
    return max(3, int(round(period / float(np.median(np.diff(t))))) | 1)


def _detrended(t: np.ndarray, y: np.ndarray, period: float) -> np.ndarray:
    """y − its median over one period about each sample: the swing without a drifting zero."""
    from scipy.ndimage import median_filter

    return y - median_filter(y, size=_width(t, period), mode="mirror")


def _envelope(t: np.ndarray, y: np.ndarray, period: float) -> np.ndarray:
    """|y − the local median| at its largest within one period of each sample (a swing's envelope)."""
    from scipy.ndimage import maximum_filter1d

    return maximum_filter1d(np.abs(_detrended(t, y, period)), size=_width(t, period), mode="nearest")


def _cuts(t: np.ndarray, y: np.ndarray, breaks: tuple[tuple[float, str], ...], noise: float,
          period: float) -> list[tuple[int, str]]:
    """(first index, what began it) of every section: the log's start, events, gaps, rests."""
    cuts: dict[int, str] = {0: "the log's start"}
    for when, what in breaks:
        i = int(np.searchsorted(t, when))
        if 0 < i < t.size:
            cuts.setdefault(i, what)
    dt = np.diff(t)
    for g in np.flatnonzero(dt > max(GAP_STEPS * float(np.median(dt)), GAP_SECONDS)):
        cuts.setdefault(int(g) + 1, f"a gap of {float(dt[g]):.3g} s")
    if math.isfinite(period):
        quiet = _envelope(t, y, period) < REST_SIGMA * noise
        edges = np.flatnonzero(np.diff(np.concatenate(([0], quiet.astype(int), [0]))))
        for a, b in zip(edges[::2], edges[1::2]):
            if t[b - 1] - t[a] >= REST_PERIODS * period and b < t.size:
                cuts.setdefault(int(b) - 1, REST)
    return sorted(cuts.items())


def _leaves_zero(t: np.ndarray, z: np.ndarray, peak_t: float, noise: float) -> float:
    """The last time before ``peak_t`` that the rate ``z`` was at zero (within the noise) or on the other side:
    where a swing that begins with this lobe was let go."""
    i = int(np.searchsorted(t, peak_t))
    sign = np.sign(z[i])
    at_zero = np.flatnonzero((np.abs(z[:i]) < 3.0 * noise) | (np.sign(z[:i]) == -sign))
    return float(t[at_zero[-1]]) if at_zero.size else float(t[0])


def free_swing_start(t: np.ndarray, y: np.ndarray, noise: float, quantity: str,
                     period: float = math.nan) -> tuple[int, str | None]:
    """Index where the free swing of one section starts, and None, or 0 and why there is no swing.

    The turning point before the first excursion of at least RELEASE_SHARE of the largest (a swing let
    go from rest is widest first; handling before it is smaller): for an angle that excursion's own
    extremum, for a rate (whose zero is the angle's turning point) the crossing before that lobe. A start
    within half a period of the section's is left at 0 (the identification's own window finds a short
    hold). The swing after it must be regular: MIN_HALF_SWINGS half-swings above SWING_SIGMA whose
    half-periods scatter less than MAX_HALF_PERIOD_SPREAD. period: the log's swing period (s), over which
    a drifting zero is taken out first (an integrated gyro's zero makes a late excursion look largest).
    """
    z = _detrended(t, y, period) if math.isfinite(period) and t.size > 3 * _width(t, period) else y
    sw = find_swings(t, z, hysteresis=SWING_SIGMA * noise)
    if sw.peak_values.size < 2:
        return 0, "no swing above the noise"
    size = np.abs(sw.peak_values)
    k = int(np.flatnonzero(size >= RELEASE_SHARE * size.max())[0])
    if quantity == "rate":
        start_t = float(sw.crossings[k - 1]) if k >= 1 else _leaves_zero(t, z, float(sw.peak_times[0]), noise)
    else:
        start_t = float(sw.peak_times[k])
    after = sw.crossings[sw.crossings > start_t]
    if after.size < MIN_HALF_SWINGS:
        return 0, f"{after.size} half-swing(s) after its largest excursion; a release has at least {MIN_HALF_SWINGS}"
    halves = np.diff(after[:MIN_HALF_SWINGS + 1])
    spread = float(np.std(halves) / np.mean(halves))
    if spread > MAX_HALF_PERIOD_SPREAD:
        return 0, f"not a free swing: its half-periods scatter {100 * spread:.0f} % (handling, not a release)"
    period = 2.0 * float(np.median(halves))
    i = max(0, int(np.searchsorted(t, start_t, side="right")) - 1)
    return (i if t[i] - t[0] > 0.5 * period else 0), None


def find_releases(t: np.ndarray, y: np.ndarray, quantity: str = "angle",
                  breaks: tuple[tuple[float, str], ...] = ()) -> Releases:
    """The releases of a log (t in s, y the reading); breaks: (time in s, what) where sections begin."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    noise = max(noise_floor(y, t=t), 1e-12 * float(np.ptp(y)) or 1e-300)
    period = _swing_period(t, y, noise)
    cuts = _cuts(t, y, breaks, noise, period)
    found: list[Release] = []
    skipped: list[Skipped] = []
    for (i0, begins), (i1, _) in zip(cuts, cuts[1:] + [(t.size, "")]):
        if i1 - i0 < 30:
            skipped.append(Skipped(float(t[i0]), float(t[i1 - 1]), f"{i1 - i0} samples"))
            continue
        ts, ys = t[i0:i1], y[i0:i1]
        start, why = free_swing_start(ts, ys, noise, quantity, period)
        if why is not None:
            skipped.append(Skipped(float(ts[0]), float(ts[-1]), why))
            continue
        centre = float(np.median(ys[start:]))
        found.append(Release(len(found) + 1, float(ts[start]), float(ts[-1]), float(ts[0]), begins,
                             float(np.max(np.abs(ys[start:] - centre))), i0 + start, i1))
    return Releases(tuple(found), tuple(skipped), noise)
