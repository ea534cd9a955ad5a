"""Step 1, preparation: the samples that are fitted, and what was learnt choosing them.

The angle is unwrapped (2π jumps of a sensor reading in (−π, π]), the noise
floor estimated from the samples' neighbour predictions, glitches screened,
and the swing's window found: release … stop, or a long gap after which the
swing does not clearly continue.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import TraceError
from ..signal import MAX_GRID_PER_SAMPLE, Swings, deviation_table, find_swings, noise_floor, spike_candidates, swing_window
from ..trace import Trace
from .options import Options


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


def gap_cut(t: np.ndarray, y: np.ndarray, noise: float, periods: float, sw: Swings) -> int | None:
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
    # a rate has no turns to unwrap
    y_all, n_unwrapped = unwrap_angle(trace.angle) if trace.quantity == "angle" else (trace.angle, 0)
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
    cut = gap_cut(t, y, noise, options.gap_periods, sw)
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
