"""SOURCE of `moi identify`: a trace CSV, a marker track CSV, a video file or an image folder, as a ``Trace``.

The dispatcher above the low-level readers: a CSV is read by ``service.sources.files``
(a marker track becomes the angle of its two markers, the camera's oblique view
measured from their distance and removed when the swing is wide enough to show it: ``measurement.vision.marker_pair``),
a video or an image folder goes through the vision path (``service.sources.video``,
imported only then: it loads OpenCV).
"""

from __future__ import annotations

import os
from pathlib import Path

from measurement.rig import Rig
from measurement.trace import Trace
from service.errors import InputFileError

from .files import read_samples

VIDEO_SUFFIXES = {".avi", ".mp4", ".mkv", ".mov", ".m4v", ".webm", ".mjpg", ".mjpeg", ".ogv"}


def load_source(path: str | os.PathLike, camera: str | os.PathLike | None = None, rig: Rig | None = None) -> Trace:
    """SOURCE of `moi identify`: a trace CSV, a marker track CSV, a video file or an image-sequence folder."""
    p = Path(path)
    if p.is_dir() or p.suffix.lower() in VIDEO_SUFFIXES:
        if camera is None:
            raise InputFileError(f"{str(p)!r} is a video source; expected --camera CAM.toml with the camera and marker geometry")
        from .video import video_trace  # the vision path: OpenCV, only for a video
        return video_trace(p, camera)
    samples = read_samples(p)
    if isinstance(samples, Trace):
        return samples
    from measurement.vision.marker_pair import view_trace

    return view_trace(samples)
