"""Video input for `moi identify VIDEO --camera CAM.toml`: track the target through a file's frames, build the trace.

The frames and their times come from the file-backed camera
(``drivers.video_file.FrameSource``, FFmpeg through PyAV); the tracking step,
the quality rules and the geometry are ``measurement.vision``'s, the same the
live camera sensor uses (``tracker_for``).
"""

from __future__ import annotations

import os

from drivers.video_file import FrameSource
from measurement.trace import Trace
from measurement.vision.config import CameraConfig
from measurement.vision.locate import TrackerSettings
from measurement.vision.pipeline import Tracking, VisionSettings, trace_from_tracking, tracker_for
from service.sources.camera import camera_config


def track_source(path: str | os.PathLike, config: CameraConfig, settings: TrackerSettings | None = None,
                 seconds: float | None = None) -> tuple[Tracking, FrameSource]:
    """Track the target through every frame of a video file or image folder (one frame in memory at a time).

    seconds: stop after the frames of the first ``seconds`` of the record (``moi camera-check``).
    """
    tracker = None
    seen = []
    with FrameSource(path, config, colour=config.target.needs_colour) as source:
        for t, frame in source:
            if seconds is not None and t is not None and t > seconds:
                break
            if tracker is None:
                # known once the stream is open: an intra-only codec's repeated rows are damage, an inter-frame
                # codec's are an unchanged region
                tracker = tracker_for(config, settings, repeated_rows_are_damage=source.intra_only)
            seen.append((t, tracker.locate(frame)))
    times = source.frame_times([t for t, _ in seen])
    tracking = Tracking()
    for t, (_, obs) in zip(times, seen):
        tracking.add(t, obs)
    return tracking, source


def source_meta(source: FrameSource) -> dict:
    """What the decoding said about a video or folder: timing, codec, frames listed/decoded/undecodable."""
    meta: dict = {"timing": source.timing, "frames_decoded": source.decoded, "undecodable_frames": source.failed}
    if source.codec:
        meta.update({"codec": source.codec, "frames_listed": source.listed})
        if source.listed > source.decoded + source.failed:
            meta["frames_not_shown"] = source.listed - source.decoded - source.failed
    if source.truncated:
        meta["stream_ended_early"] = source.truncated
    return meta


def video_trace(path: str | os.PathLike, camera: str | os.PathLike | CameraConfig,
                settings: TrackerSettings | None = None, vision: VisionSettings | None = None) -> Trace:
    """The angle trace (t in s, angle in rad) of the target in a video file or image folder.

    camera: the camera file (TOML) or a parsed ``CameraConfig``. ``Trace.meta["camera"]`` reports the
    frame counts, the tracking quality and what the geometry measured (yaw, pivot, view).
    """
    config = camera_config(camera)
    tracking, source = track_source(path, config, settings)
    return trace_from_tracking(tracking, config, source=str(path), settings=vision, dropped=source.dropped,
                               extra_meta={**source_meta(source),
                                           "camera_file": None if isinstance(camera, CameraConfig) else str(camera)})
