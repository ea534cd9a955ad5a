"""How well the target was tracked: the share of frames, the longest gap, the jitter, the jumps.

Part of the answer, not a footnote: a swing identified from a tenth of its
frames, or from a track that jumped to a wall stripe and back, is not a
measurement. The rules (``assess``):

* share: tracked frames over the frames that decoded. Below ``MIN_SHARE``
  (80 %) the video is refused (``VisionError``, exit status 2) with the
  longest gap and the reasons frames were lost.
* jumps: a tracked angle that leaves the smooth path of its neighbours (its
  distance from the cubic through the two samples on either side exceeds
  ``JUMP_SIGMAS`` times the track's jitter and ``JUMP_SHARE`` of the swing's
  range) is a tracking error: dropped and counted. More than ``MAX_JUMPS``
  of the samples jumping is a refusal (the frames are named).
* motion: a target that never moves (its range within ``STILL_SIGMAS`` ×
  jitter, or under ``STILL_RANGE``) is refused: it is not the swinging body.
* jitter: the robust σ of that cubic's residual scaled to one sample
  (rad), reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import VisionError

#: least share of the decodable frames in which the target must be found
MIN_SHARE = 0.80
#: a sample this many jitter σ off the cubic through its neighbours is a jump
JUMP_SIGMAS = 8.0
#: ... and at least this share of the swing's range
JUMP_SHARE = 0.05
#: most samples that may be jumps before the track is refused
MAX_JUMPS = 0.02
#: a swing within this many jitter σ (or under STILL_RANGE rad) is a target that does not move
STILL_SIGMAS = 10.0
STILL_RANGE = 1e-3
#: ... and a target whose image point moves less than this (px), when its position is what is judged
STILL_PX = 0.5
#: the neighbours of a sample judged for a jump lie within this many frame periods
SPAN_PERIODS = 6.0
# the residual of the cubic through samples i−2, i−1, i+1, i+2 at i is a combination of 5 samples
# with weights (1, −4, 6, −4, 1)/6: its σ is √70/6 times one sample's
_RESIDUAL_GAIN = math.sqrt(70.0) / 6.0


@dataclass(frozen=True)
class TrackQuality:
    """decoded: frames that decoded (duplicates of the previous picture left out); tracked: frames with the target; share = tracked/decoded.
    longest_gap_s, gap_from_s: the longest stretch without the target (s) and where it starts (s).
    jitter_rad: σ of one sample about the smooth swing (rad); jumps: samples dropped as jumps;
    jump_times_s: their times (s, first ones)."""

    decoded: int
    tracked: int
    longest_gap_s: float
    gap_from_s: float
    jitter_rad: float
    jumps: int
    jump_times_s: tuple[float, ...] = ()

    @property
    def share(self) -> float:
        return self.tracked / self.decoded if self.decoded else 0.0

    def to_dict(self) -> dict:
        return {"frames_decoded": self.decoded, "frames_tracked": self.tracked, "tracked_share": round(self.share, 4),
                "min_tracked_share": MIN_SHARE, "longest_gap_s": round(self.longest_gap_s, 4),
                "longest_gap_from_s": round(self.gap_from_s, 4),
                "jitter_rad": float(f"{self.jitter_rad:.3g}") if math.isfinite(self.jitter_rad) else None,
                "jumps": self.jumps}


def _jump_residual(t: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Distance of each sample from the cubic through its two neighbours on each side, at their own times
    (frames may be missing); 0 at the ends and where the neighbours span more than ``SPAN_PERIODS`` frame
    periods (across a gap a cubic says nothing)."""
    r = np.zeros_like(theta)
    if theta.size < 5:
        return r
    x = t[2:-2]
    nodes = [t[:-4], t[1:-3], t[3:-1], t[4:]]
    values = [theta[:-4], theta[1:-3], theta[3:-1], theta[4:]]
    fit = np.zeros_like(x)
    for j in range(4):
        w = np.ones_like(x)
        for k in range(4):
            if k != j:
                w *= (x - nodes[k]) / (nodes[j] - nodes[k])
        fit += w * values[j]
    period = float(np.median(np.diff(t)))
    judged = (nodes[3] - nodes[0]) <= SPAN_PERIODS * period
    r[2:-2] = np.where(judged, theta[2:-2] - fit, 0.0)
    return r


@dataclass(frozen=True)
class Motion:
    """How far a tracked quantity went (span: its range) against its jitter (σ of one sample about the smooth
    path), in the quantity's unit (rad for an angle, px for an image position); moves: the span is more than
    ``STILL_SIGMAS`` jitter σ and more than the floor for the unit."""

    span: float
    jitter: float
    floor: float

    @property
    def moves(self) -> bool:
        return self.span > max(STILL_SIGMAS * (self.jitter if math.isfinite(self.jitter) else 0.0), self.floor)


def motion(t: np.ndarray, values: np.ndarray, floor: float = STILL_RANGE) -> Motion:
    """The motion of ``values`` (one per tracked time t, s); floor: ``STILL_RANGE`` for an angle (rad),
    ``STILL_PX`` for a position (px)."""
    t = np.asarray(t, dtype=float)
    values = np.asarray(values, dtype=float)
    r = _jump_residual(t, values)
    inner = r[2:-2][r[2:-2] != 0] if r.size >= 5 else r
    jitter = 1.4826 * float(np.median(np.abs(inner))) / _RESIDUAL_GAIN if inner.size else math.nan
    return Motion(span=float(np.ptp(values)) if values.size else 0.0, jitter=jitter, floor=floor)


def _gaps(t_tracked: np.ndarray, t_all: np.ndarray) -> tuple[float, float]:
    """The longest stretch of the record without a tracked frame (s) and where it starts (s)."""
    if t_all.size == 0:
        return 0.0, 0.0
    edges = np.concatenate([[t_all.min()], t_tracked, [t_all.max()]]) if t_tracked.size else np.array([t_all.min(), t_all.max()])
    d = np.diff(edges)
    period = float(np.median(np.diff(t_all))) if t_all.size > 1 else 0.0
    k = int(np.argmax(d))
    return max(float(d[k]) - period, 0.0), float(edges[k])


def assess(t_all: np.ndarray, t: np.ndarray, theta: np.ndarray, *, source: str = "video",
           reasons: str = "", repeated: int = 0) -> tuple[np.ndarray, TrackQuality]:
    """Check a track (tracked times t and angles theta, rad; t_all: the times of every decoded frame, s;
    repeated: frames that only repeated the previous picture, which are not counted as frames).

    Returns the mask of samples to keep (jumps dropped) and the quality. Raises VisionError with the
    frames and the reason when the track is too sparse, jumps too often, or does not move.
    """
    t_all = np.asarray(t_all, dtype=float)
    t = np.asarray(t, dtype=float)
    theta = np.asarray(theta, dtype=float)
    decoded = max(int(t_all.size) - repeated, int(t.size))
    gap, gap_from = _gaps(t, t_all)
    share = t.size / decoded if decoded else 0.0
    why = f" ({reasons})" if reasons else ""
    if share < MIN_SHARE:
        raise VisionError(f"{source}: the target was tracked in {100 * share:.0f} % of {decoded} decoded frames"
                          f"{why}, longest gap {gap:.2f} s from {gap_from:.2f} s; expected at least "
                          f"{100 * MIN_SHARE:.0f} % (set the target and its region of interest in the camera "
                          "file; check with `moi camera-check`)")
    r = _jump_residual(t, theta)
    moved = motion(t, theta)
    jitter, swing = moved.jitter, moved.span
    if not moved.moves:
        raise VisionError(f"{source}: the target does not move (its track spans {swing:.2g} over "
                          f"{t.size} frames, jitter {jitter:.2g}); expected the swinging body: is the "
                          "target on it (check with `moi camera-check`)?")
    limit = max(JUMP_SIGMAS * _RESIDUAL_GAIN * jitter, JUMP_SHARE * swing)
    jump = np.abs(r) > limit
    # a jump shows in its neighbours' residuals too: keep the worst of each run
    worst = jump & (np.abs(r) >= np.maximum(np.roll(np.abs(r), 1), np.roll(np.abs(r), -1)))
    if worst.sum() > MAX_JUMPS * t.size:
        at = ", ".join(f"{x:.2f}" for x in t[worst][:6])
        raise VisionError(f"{source}: the track jumps in {int(worst.sum())} of {t.size} frames (at {at} s…): "
                          f"more than {100 * MAX_JUMPS:.0f} %; expected the target followed smoothly (another "
                          "object in the region of interest? set the region or the target in the camera file)")
    quality = TrackQuality(decoded=decoded, tracked=int(t.size - worst.sum()), longest_gap_s=gap,
                           gap_from_s=gap_from, jitter_rad=jitter, jumps=int(worst.sum()),
                           jump_times_s=tuple(float(x) for x in t[worst][:10]))
    return ~worst, quality
