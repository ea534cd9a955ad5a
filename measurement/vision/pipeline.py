"""Frames to an angle trace: track the marker, convert with the exact geometry, correct the camera yaw.

Pure: the caller decodes the frames (``drivers/video_file.py`` from a file,
``drivers/camera.py`` live) and hands over (time, grey frame) pairs; a
frame that could not be decoded is passed as ``None`` and counted as
corrupt. Frames without a marker leave a gap in the trace (timestamps may
be uneven) and a flag, never an exception.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Iterable

import numpy as np

from ..errors import VisionError
from ..flags import CAMERA_POSE, DROPPED_FRAMES
from ..trace import Trace
from .body import body_trace
from .config import CameraConfig
from .geometry import angle_from_normalised
from .locate import CORRUPT, LOST, MarkerObservation, MarkerTracker, TrackerSettings
from .locators import REPEATED, Locator, PointObservation, make_locator
from .pose import PoseEstimate, estimate_yaw
from .quality import assess

DROPPED = DROPPED_FRAMES
POSE = CAMERA_POSE


#: a gap between two frames longer than this many frame periods means frames were lost (shorter: jitter)
DROP_GAP = 1.5


class DropCounter:
    """Counts the frames missing between consecutive timestamps of a camera running at ``fps`` frames/s.

    The one rule for dropped frames: a gap of n frame periods (rounded) hides n − 1 frames; gaps
    up to ``DROP_GAP`` periods are jitter, not drops. Used live (the V4L2 camera numbers its
    frames with it) and on a finished record (``count_dropped``).
    """

    def __init__(self, fps: float):
        self.period = 1.0 / fps
        self.last: float | None = None
        self.dropped = 0

    def add(self, t: float) -> int:
        """Record a frame time (s); returns how many frames went missing just before it."""
        missing = 0
        if self.last is not None:
            gap = (t - self.last) / self.period
            if gap > DROP_GAP:
                missing = int(round(gap)) - 1
                self.dropped += missing
        self.last = t
        return missing


def count_dropped(t: np.ndarray, fps: float) -> int:
    """Frames missing from timestamps t (s, increasing) of a camera running at ``fps`` frames/s (``DropCounter``)."""
    if not fps > 0:
        return 0
    counter = DropCounter(fps)
    for x in np.asarray(t, dtype=float):
        counter.add(float(x))
    return counter.dropped


@dataclass
class Tracking:
    """The marker's track over a sequence of frames (what the tracker saw, before any geometry).

    t: s, frame times of the frames where the marker was found; x: ideal normalised coordinate there.
    slope: the edge's dx/dy per found frame; rows, residual: rows used and line RMS (px) per found frame.
    frames: frames offered (decoded or not); lost, corrupt: frames without a position.
    reasons: why frames failed (first words of the tracker's detail) → count.
    seen_times: s, every frame that had a timestamp; untimed: frames that had none (undecodable).
    a, b: the body vector's ends per found frame, px (a None: a single blob); repeated: frames that showed
    the target exactly where the previous one did (duplicated frames, not measurements).
    """

    t: list[float] = field(default_factory=list)
    x: list[float] = field(default_factory=list)
    slope: list[float] = field(default_factory=list)
    rows: list[int] = field(default_factory=list)
    residual: list[float] = field(default_factory=list)
    contrast: list[float] = field(default_factory=list)
    frames: int = 0
    lost: int = 0
    corrupt: int = 0
    reasons: Counter = field(default_factory=Counter)
    seen_times: list[float] = field(default_factory=list)
    untimed: int = 0
    a: list[tuple[float, float] | None] = field(default_factory=list)
    b: list[tuple[float, float]] = field(default_factory=list)
    repeated: int = 0

    def _repeats(self, obs: MarkerObservation | PointObservation) -> bool:
        """The target sits exactly where it sat in the last tracked frame (to 1e-9 px): a duplicated frame."""
        if not self.t:
            return False
        if isinstance(obs, PointObservation):
            if not self.b or obs.b is None:
                return False
            pa = self.a[-1]
            same_a = (obs.a is None and pa is None) or (obs.a is not None and pa is not None
                                                        and abs(obs.a[0] - pa[0]) + abs(obs.a[1] - pa[1]) < 1e-9)
            return same_a and abs(obs.b[0] - self.b[-1][0]) + abs(obs.b[1] - self.b[-1][1]) < 1e-9
        return bool(self.x) and obs.x == self.x[-1] and obs.slope == self.slope[-1]

    @property
    def decoded_times(self) -> np.ndarray:
        """Times (s) of the frames that decoded (the denominator of the tracked share)."""
        return np.unique(np.asarray(self.seen_times, dtype=float))

    def reasons_text(self, n: int = 3) -> str:
        """The commonest reasons frames gave no position, with their counts."""
        return ", ".join(f"{k} ×{c}" for k, c in self.reasons.most_common(n))

    def add(self, t: float | None, obs: MarkerObservation | PointObservation) -> bool:
        """The tracking step of one frame (time in s or None, its observation): True when it gave a position.

        A position with a missing, repeated or out-of-order time cannot be placed in a trace and
        counts as corrupt; a frame without the marker counts as lost (or corrupt, by its reason).
        """
        self.frames += 1
        if t is not None and math.isfinite(t):
            self.seen_times.append(float(t))
        else:
            self.untimed += 1
        if obs.reason == REPEATED:
            self.repeated += 1
            return False
        if obs.found and t is not None and math.isfinite(t):
            if self._repeats(obs):
                # the previous picture again (a phone's frame-rate conversion duplicates frames; the codec
                # stores the copy as "unchanged"): no new measurement, and its time would be wrong
                self.repeated += 1
                return False
            if self.t and t <= self.t[-1]:
                # a repeated or out-of-order timestamp cannot be placed in a trace
                self.corrupt += 1
                self.reasons["timestamp out of order"] += 1
                return False
            self.t.append(float(t))
            if isinstance(obs, PointObservation):
                assert obs.b is not None, "a found target has its point b"
                self.a.append(obs.a)
                self.b.append(obs.b)
                return True
            self.x.append(obs.x)
            self.slope.append(obs.slope)
            self.rows.append(obs.rows)
            self.residual.append(obs.residual)
            self.contrast.append(obs.contrast)
            return True
        if obs.reason == CORRUPT or t is None:
            self.corrupt += 1
        else:
            self.lost += 1
        self.reasons[(obs.detail or obs.reason or "no marker").split(" (")[0]] += 1
        return False

    def subset(self, keep: np.ndarray) -> "Tracking":
        """A copy keeping only the positions where the boolean mask ``keep`` (one per position) is true;
        the frame counters are copied unchanged."""
        pick = np.flatnonzero(keep)

        def take(values: list) -> list:
            return [values[i] for i in pick] if values else []

        return Tracking(t=take(self.t), x=take(self.x), slope=take(self.slope), rows=take(self.rows),
                        residual=take(self.residual), contrast=take(self.contrast), frames=self.frames,
                        lost=self.lost, corrupt=self.corrupt, reasons=Counter(self.reasons),
                        seen_times=list(self.seen_times), untimed=self.untimed, a=take(self.a), b=take(self.b),
                        repeated=self.repeated)


def tracker_for(config: CameraConfig, settings: TrackerSettings | None = None, *,
                repeated_rows_are_damage: bool = True) -> MarkerTracker | Locator:
    """The tracker of the camera file's target: ``MarkerTracker`` for the edge (its region of interest from the
    file), a locator (``locators.make_locator``) for the others. repeated_rows_are_damage: the frames come from
    an intra-only codec (MJPEG), where rows repeated bit for bit are the decoder concealing a damaged frame."""
    spec = config.target
    if not config.edge:
        return make_locator(spec, config.camera.width, config.camera.height)
    settings = settings or TrackerSettings()
    settings = replace(settings, reject_repeated=settings.reject_repeated and repeated_rows_are_damage,
                       roi=settings.roi if settings.roi is not None else spec.roi)
    return MarkerTracker(config.camera, settings)


def track_frames(frames: Iterable[tuple[float | None, np.ndarray | None]], config: CameraConfig,
                 settings: TrackerSettings | None = None) -> Tracking:
    """Run the target's tracker over (time in s, frame) pairs; ``None`` frames count as corrupt."""
    tracker = tracker_for(config, settings)
    out = Tracking()
    for t, frame in frames:
        out.add(t, tracker.locate(frame))
    return out


@dataclass(frozen=True)
class VisionSettings:
    """How a track becomes a trace.

    estimate_yaw: fit the camera yaw from the swing and correct the angles with it.
    yaw: a known yaw, rad, used when not estimating.
    yaw_limit_deg: |yaw| above which the trace is flagged ``camera_pose``, degrees.
    """

    estimate_yaw: bool = True
    yaw: float = 0.0
    yaw_limit_deg: float = 2.0

    @classmethod
    def from_config(cls, config: CameraConfig) -> "VisionSettings":
        return cls(estimate_yaw=config.pose.estimate, yaw_limit_deg=config.pose.yaw_limit_deg)


def _flags_and_counts(tracking: Tracking, config: CameraConfig, dropped: int | None) -> tuple[list[str], dict]:
    if dropped is None:
        # an undecodable frame still took its slot in the stream: it is not a dropped one
        dropped = max(count_dropped(np.unique(tracking.seen_times), config.camera.fps or 0.0) - tracking.untimed, 0)
    flags: list[str] = []
    if tracking.lost:
        flags.append(LOST)
    if tracking.corrupt:
        flags.append(CORRUPT)
    if dropped:
        flags.append(DROPPED)
    return flags, {"frames": tracking.frames, "marker_lost": tracking.lost, "corrupt_frames": tracking.corrupt,
                   "repeated_frames": tracking.repeated,
                   "dropped_frames": int(dropped), "failures": dict(tracking.reasons)}


def _too_few(tracking: Tracking, source: str) -> None:
    if len(tracking.t) < 2:
        if tracking.repeated >= tracking.frames // 2:
            raise VisionError(f"{source}: the target does not move: {tracking.repeated} of {tracking.frames} frames "
                              "repeat the previous picture; expected the swinging body in view (check with "
                              "`moi camera-check`)")
        raise VisionError(f"{source}: the target was found in {len(tracking.t)} of {tracking.frames} frames "
                          f"({tracking.reasons_text() or 'no frames'}); expected the target in view (check with "
                          "`moi camera-check`)")


def trace_from_tracking(tracking: Tracking, config: CameraConfig, *, source: str = "video",
                        settings: VisionSettings | None = None, dropped: int | None = None,
                        extra_meta: dict | None = None) -> Trace:
    """The angle trace (rad) of a track, its quality checked (``quality.assess``: refused when sparse,
    jumping or still; jumps dropped) and in ``meta["camera"]["tracking"]``.

    The edge: exact cylinder geometry, yaw estimated and corrected. The other targets: the direction of
    their body vector, the oblique view removed (``body``). dropped: frames the acquisition knows it
    lost (None: counted from timestamp gaps at the camera's fps). Flags: ``marker_lost``,
    ``corrupt_frame``, ``dropped_frames``, ``camera_pose``. Raises VisionError naming what was wrong.
    """
    _too_few(tracking, source)
    if not config.edge:
        return _points_trace(tracking, config, source=source, dropped=dropped, extra_meta=extra_meta)
    return _edge_trace(tracking, config, source=source, settings=settings, dropped=dropped, extra_meta=extra_meta)


def _points_trace(tracking: Tracking, config: CameraConfig, *, source: str, dropped: int | None,
                  extra_meta: dict | None) -> Trace:
    t = np.asarray(tracking.t, dtype=float)
    b = np.asarray(tracking.b, dtype=float)
    single = tracking.a[0] is None
    spec = config.target
    if single:
        # a provisional pivot for the jump test: the given one, else straight above the track's middle
        pu, pv = spec.pivot if spec.pivot is not None else (float(np.median(b[:, 0])), float(b[:, 1].min()) - 10 * float(np.ptp(b[:, 0]) + 1))
        a = np.tile([pu, pv], (len(b), 1))
    else:
        a = np.asarray(tracking.a, dtype=float)
    raw = np.unwrap(np.arctan2(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]))
    keep, quality = assess(tracking.decoded_times, t, raw, source=source, reasons=tracking.reasons_text(),
                           repeated=tracking.repeated)
    trace, measured = body_trace(t[keep], None if single else a[keep], b[keep], pivot=spec.pivot, source=source,
                                 missing=tracking.lost + tracking.corrupt)
    flags, counts = _flags_and_counts(tracking, config, dropped)
    camera_meta = {**counts, "frames_used": int(keep.sum()), "target": spec.to_dict(), "tracking": quality.to_dict(),
                   **measured, **{k: v for k, v in trace.meta.items() if k in ("view", "view_note")}}
    if extra_meta:
        camera_meta.update(extra_meta)
    flags += [f for f in trace.flags if f not in flags]
    meta: dict = {"sensor": "camera", "camera": camera_meta}
    if "view" in trace.meta:
        meta["view"] = trace.meta["view"]  # measured: the identification does not fit the scale again
    return Trace(trace.t, trace.angle, source=source, flags=tuple(flags), meta=meta)


def _edge_trace(tracking: Tracking, config: CameraConfig, *, source: str, settings: VisionSettings | None,
                dropped: int | None, extra_meta: dict | None) -> Trace:
    settings = settings or VisionSettings.from_config(config)
    keep, quality = assess(tracking.decoded_times, np.asarray(tracking.t), np.asarray(tracking.x), source=source,
                           reasons=tracking.reasons_text(), repeated=tracking.repeated)
    tracking = tracking.subset(keep)
    t = np.asarray(tracking.t, dtype=float)
    x = np.asarray(tracking.x, dtype=float)
    marker = config.cylinder
    pose = PoseEstimate(False, reason="yaw estimation switched off; using the configured yaw")
    yaw, rest = settings.yaw, 0.0
    if settings.estimate_yaw:
        pose = estimate_yaw(t, x, marker)
        if pose.estimated:
            yaw, rest = pose.yaw, pose.rest_angle
    theta = angle_from_normalised(x, marker, yaw, rest)
    bad = ~np.isfinite(theta)
    if bad.any():
        # a position beyond the cylinder's silhouette: the geometry in the camera file is wrong for it
        tracking.lost += int(bad.sum())
        tracking.reasons["beyond the cylinder's silhouette"] += int(bad.sum())
        t, theta, x = t[~bad], theta[~bad], x[~bad]
    if t.size < 2:
        raise VisionError(f"{source}: no marker position fits the geometry of the camera file "
                          f"(radius {marker.radius} m, distance {marker.distance} m)")
    flags, counts = _flags_and_counts(tracking, config, dropped)
    yaw_reported = pose.yaw if pose.estimated else settings.yaw
    if abs(math.degrees(yaw_reported)) > settings.yaw_limit_deg:
        flags.append(POSE)
    slope = np.asarray(tracking.slope)
    camera_meta = {
        **counts, "frames_used": int(t.size), "tracking": quality.to_dict(),
        "yaw_deg": round(math.degrees(yaw_reported), 4), "yaw_limit_deg": settings.yaw_limit_deg,
        "yaw_corrected": bool(pose.estimated),
        **{k: v for k, v in pose.to_dict().items() if k != "yaw_deg"},
        "marker_tilt_deg": round(float(np.degrees(np.arctan(np.median(slope)))), 3) if slope.size else None,
        "edge_rows_median": float(np.median(tracking.rows)) if tracking.rows else None,
        "edge_line_rms_px": round(float(np.median(tracking.residual)), 4) if tracking.residual else None,
        "edge_strength_grey": round(float(np.median(tracking.contrast)), 1) if tracking.contrast else None,
        "radius_m": marker.radius, "distance_m": marker.distance,
    }
    if extra_meta:
        camera_meta.update(extra_meta)
    return Trace(t, theta, source=source, flags=tuple(flags), meta={"sensor": "camera", "camera": camera_meta})
