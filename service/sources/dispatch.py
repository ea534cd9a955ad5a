"""SOURCE of `moi identify`: a trace CSV, a marker track CSV, an export of another tool, a video file or an
image folder, as the ``Trace`` of each release it holds.

The dispatcher above the low-level readers: moi's own CSV (t with angle or rate; a marker track) is read by
``service.sources.files`` (split into its releases when it holds several; a marker track becomes the angle of its two markers, the camera's oblique view
measured from their distance and removed when the swing is wide enough to show it:
``measurement.vision.marker_pair``); any other table or export by the first format of
``service.sources.formats.registry`` that recognises its content, split into its releases; a video or an
image folder goes through the vision path (``service.sources.video``, imported only then: it loads OpenCV).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from measurement.releases import REST, find_releases
from measurement.rig import Rig
from measurement.trace import READING_UNITS, Trace, csv_content, csv_header
from service.errors import InputFileError

from .files import read_samples
from .formats.columns import ColumnChoice

VIDEO_SUFFIXES = {".avi", ".mp4", ".mkv", ".mov", ".m4v", ".webm", ".mjpg", ".mjpeg", ".ogv"}


def _is_moi_csv(p: Path) -> bool:
    """A file whose header is moi's trace (t and angle or rate) or marker track columns."""
    from measurement.vision.marker_pair import MARKER_COLUMNS

    if p.is_dir() or not p.is_file():
        return False
    with open(p, "rb") as f:
        head = f.read(8192).decode("utf-8-sig", errors="replace")
    lines = head.splitlines()[:-1] or head.splitlines()
    cells = set(csv_header(csv_content(lines)))
    return "t" in cells and bool({"angle", "rate"} & cells or set(MARKER_COLUMNS) <= cells)


def _is_image_folder(p: Path) -> bool:
    return p.is_dir() and not any(p.rglob("time.csv"))


def _own_trace_releases(trace: Trace) -> list[Trace]:
    """moi's own trace whole, as the sequencer captured it (its pre-trigger hold is the identification's to
    handle), unless it holds several releases: then each of them, read as a log's are (the hold before each
    and the hand's transient cut), so that several swings saved in one file are never fitted as one."""
    # a gap in moi's own record is a sensor's dropout within one swing (the identification cuts its window
    # there and says so); a rest before a swing is a new release
    if not any(r.begins == REST for r in find_releases(trace.t, trace.angle, trace.quantity).found[1:]):
        return [trace]
    from .formats.log import Column, Log
    from .formats.reading import log_traces

    q = trace.quantity
    log = Log(trace.source, "moi trace", (Column("t", "t", "s"), Column(q, q, READING_UNITS[q])),
              np.column_stack([trace.t, trace.angle]))
    return log_traces(log, ColumnChoice(time="t", angle=q if q == "angle" else None, rate=q if q == "rate" else None))


def load_releases(path: str | os.PathLike, camera: str | os.PathLike | None = None, rig: Rig | None = None,
                  columns: ColumnChoice | None = None) -> list[Trace]:
    """The releases in SOURCE, each a trace: one for moi's CSV and a video, as many as a log holds otherwise."""
    p = Path(path)
    columns = columns or ColumnChoice()
    if _is_image_folder(p) or p.suffix.lower() in VIDEO_SUFFIXES:
        if camera is None:
            raise InputFileError(f"{str(p)!r} is a video source; expected --camera CAM.toml with the camera and marker geometry")
        from .video import video_trace  # the vision path: OpenCV, only for a video
        return [video_trace(p, camera)]
    if not p.exists():
        raise InputFileError(f"trace {str(p)!r} not found")
    if not columns.given and _is_moi_csv(p):
        samples = read_samples(p)
        if isinstance(samples, Trace):
            return _own_trace_releases(samples)
        from measurement.vision.marker_pair import view_trace

        return [view_trace(samples)]
    from .formats.reading import log_traces
    from .formats.registry import read_log

    return log_traces(read_log(p), columns)


def load_source(path: str | os.PathLike, camera: str | os.PathLike | None = None, rig: Rig | None = None) -> Trace:
    """SOURCE holding one release (InputFileError naming how many it holds otherwise)."""
    traces = load_releases(path, camera, rig)
    if len(traces) > 1:
        raise InputFileError(f"{str(path)!r} holds {len(traces)} releases; expected one (moi identify takes them "
                             "all, or one with --release N)")
    return traces[0]
