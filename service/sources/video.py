"""Video input for `moi identify VIDEO --camera CAM.toml`: track the marker through a file's frames, build the trace.

The frames and their times come from the file-backed camera
(``drivers.video_file.FrameSource``); the tracking step and the geometry are
``measurement.vision.pipeline``'s, the same the live camera sensor uses.
"""

from __future__ import annotations

import os

from drivers.video_file import FrameSource
from measurement.trace import Trace
from measurement.vision.config import CameraConfig
from measurement.vision.locate import MarkerTracker, TrackerSettings
from measurement.vision.pipeline import Tracking, VisionSettings, trace_from_tracking

from service.config.camera import camera_config


def track_source(path: str | os.PathLike, config: CameraConfig,
                 settings: TrackerSettings = TrackerSettings()) -> tuple[Tracking, FrameSource]:
    """Track the marker through every frame of a video file or image folder (one frame in memory at a time)."""
    source = FrameSource(path, config)
    tracker = MarkerTracker(config.camera, settings)
    seen = [(t, tracker.locate(frame)) for t, frame in source]
    times = source.frame_times([t for t, _ in seen])
    tracking = Tracking()
    for t, (_, obs) in zip(times, seen):
        tracking.add(t, obs)
    return tracking, source


def video_trace(path: str | os.PathLike, camera: str | os.PathLike | CameraConfig,
                settings: TrackerSettings = TrackerSettings(), vision: VisionSettings | None = None) -> Trace:
    """The angle trace (t in s, angle in rad) of the marker in a video file or image folder.

    camera: the camera file (TOML) or a parsed ``CameraConfig``. The camera
    yaw is estimated from the swing and corrected (see measurement.vision.pose);
    ``Trace.meta["camera"]`` reports it with the frame counts.
    """
    config = camera_config(camera)
    tracking, source = track_source(path, config, settings)
    return trace_from_tracking(tracking, config, source=str(path), settings=vision, dropped=source.dropped,
                               extra_meta={"timing": source.timing,
                                           "camera_file": None if isinstance(camera, CameraConfig) else str(camera)})
