"""The file-backed camera: frames of a video file or an image folder, with their times.

What ``moi identify VIDEO --camera CAM.toml`` and ``moi camera-check --source``
read (``service.sources.video`` tracks the marker in them). Sources: any container
OpenCV's FFmpeg backend reads (AVI, MP4, MKV, MOV…) or a folder of images (PNG, JPEG, BMP, TIFF, PGM) taken in name order
(numbers in names compare as numbers).

Frame times: a video's come from its container (presentation timestamps).
When they lie on the grid of the container's frame rate within its
rounding (MKV stores whole milliseconds), they are snapped to that grid:
the rounding is timing noise the camera did not have. Grid slots with no
frame are dropped frames. A folder's frames are 1/fps apart (fps from the
camera file) unless it holds ``timestamps.csv`` with columns ``file`` and
``t`` (s).

A frame that does not decode counts as corrupt (so does one whose marker
rows repeat the previous frame bit for bit: FFmpeg's concealment of a
damaged frame, see ``MarkerTracker``), a frame without the marker as lost;
both leave gaps in the trace and a flag.
"""

from __future__ import annotations

import csv
import math
import os
import re
from pathlib import Path
from typing import Iterator

import numpy as np

from measurement.errors import VisionError
from measurement.vision.config import CameraConfig
from measurement.vision.locate import to_grey
from measurement.vision.pipeline import count_dropped

from .errors import VideoFileError

# FFmpeg reports every damaged packet on stderr; the count goes into the result instead.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

import cv2  # after the log level, which FFmpeg reads when first used

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm"}
TIMESTAMPS_FILE = "timestamps.csv"
#: consecutive undecodable frames after which a stream is taken to have ended
MAX_CONSECUTIVE_FAILURES = 25


def _natural_key(name: str) -> list:
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", name)]


class FrameSource:
    """Frames of a video file or an image folder as (t in s or None, grey uint8 frame or None).

    After iteration: ``count`` frames offered, ``failed`` undecodable ones, ``timing`` how times
    were obtained, ``dropped`` frames missing from the stream.
    """

    def __init__(self, path: str | os.PathLike, config: CameraConfig):
        self.path = Path(path)
        self.config = config
        self.count = 0
        self.failed = 0
        self.dropped = 0
        self.timing = ""
        self._fps = config.camera.fps
        if not self.path.exists():
            raise VideoFileError(f"video {str(self.path)!r} not found")

    def __iter__(self) -> Iterator[tuple[float | None, np.ndarray | None]]:
        if self.path.is_dir():
            yield from self._folder()
        else:
            yield from self._video()

    # -- image folder -------------------------------------------------------
    def _folder(self) -> Iterator[tuple[float | None, np.ndarray | None]]:
        files = sorted((p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES),
                       key=lambda p: _natural_key(p.name))
        if not files:
            raise VideoFileError(f"image folder {str(self.path)!r} holds no images "
                                 f"({', '.join(sorted(IMAGE_SUFFIXES))})")
        times = self._folder_times(files)
        self.timing = "timestamps.csv" if (self.path / TIMESTAMPS_FILE).exists() else f"1/fps (fps = {self.config.camera.fps:g})"
        self.dropped = count_dropped(np.asarray(times), self.config.camera.fps)
        for p, t in zip(files, times):
            self.count += 1
            img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            if img is None:
                self.failed += 1
            yield t, img

    def _folder_times(self, files: list[Path]) -> list[float]:
        ts = self.path / TIMESTAMPS_FILE
        if not ts.exists():
            return [i / self.config.camera.fps for i in range(len(files))]
        with ts.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(line for line in fh if not line.lstrip().startswith("#")))
        if not rows or not {"file", "t"} <= set(rows[0]):
            raise VideoFileError(f"{ts}: expected columns file and t (s)")
        table = {}
        for n, row in enumerate(rows, start=2):
            try:
                table[row["file"].strip()] = float(row["t"])
            except (TypeError, ValueError):
                raise VideoFileError(f"{ts}: line {n}: t must be a number in s, got {row.get('t')!r}") from None
        missing = [p.name for p in files if p.name not in table]
        if missing:
            raise VideoFileError(f"{ts}: no time for {missing[0]}" + (f" and {len(missing) - 1} more" if len(missing) > 1 else ""))
        return [table[p.name] for p in files]

    # -- video file -------------------------------------------------------
    def _video(self) -> Iterator[tuple[float | None, np.ndarray | None]]:
        """Container times are yielded raw; ``frame_times`` turns them into the trace's times afterwards."""
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            raise VideoFileError(f"video {str(self.path)!r} cannot be opened (not a video OpenCV can decode)")
        try:
            total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
            fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
            self._fps = fps if math.isfinite(fps) and 0 < fps < 10000 else self.config.camera.fps
            pending = 0  # failed grabs not yet known to be damage rather than the end
            first = True
            while True:
                if not cap.grab():
                    # FFmpeg fails a damaged frame and goes on with the next one; at the end of the
                    # stream every grab fails.
                    pending += 1
                    if (total and self.count + pending > total) or pending > MAX_CONSECUTIVE_FAILURES:
                        break
                    continue
                for _ in range(pending):
                    self.count += 1
                    self.failed += 1
                    yield None, None
                pending = 0
                ok, frame = cap.retrieve()
                t_ms = cap.get(cv2.CAP_PROP_POS_MSEC)
                self.count += 1
                if not ok or frame is None:
                    self.failed += 1
                    yield None, None
                    continue
                grey = to_grey(frame)
                if first and grey.shape != (self.config.camera.height, self.config.camera.width):
                    raise VisionError(f"video {str(self.path)!r} is {grey.shape[1]}×{grey.shape[0]} px; the camera "
                                      f"file says {self.config.camera.width}×{self.config.camera.height}")
                first = False
                yield (t_ms / 1000.0 if math.isfinite(t_ms) else None), grey
        finally:
            cap.release()
        if self.count == 0:
            raise VideoFileError(f"video {str(self.path)!r} has no frames")

    def frame_times(self, pts: list[float | None]) -> list[float | None]:
        """Times (s) of the frames yielded, from their raw times (None: undecodable frame).

        Video: container times, snapped to the frame-rate grid when they are on it within the
        container's rounding; sets ``timing`` and ``dropped``. Folder: the times as read.
        """
        if self.path.is_dir():
            return pts
        fps = self._fps
        known = np.array([p for p in pts if p is not None], dtype=float)
        if known.size >= 2 and np.all(np.diff(known) > 0):
            t0 = known[0]
            slots = np.rint((known - t0) * fps)
            off_grid = np.abs(known - t0 - slots / fps)
            if off_grid.max() <= min(1e-3, 0.1 / fps) and np.all(np.diff(slots) > 0):
                self.timing = f"container, on the {fps:g} frames/s grid"
                # undecodable frames held slots too; only the rest of the missing slots were dropped
                self.dropped = max(int(slots[-1] - slots[0] + 1) - known.size - self.failed, 0)
                snapped = iter(t0 + slots / fps)
                return [None if p is None else float(next(snapped)) for p in pts]
            self.timing = "container (variable frame rate)"
            self.dropped = max(count_dropped(known, fps) - self.failed, 0)
            return pts
        # no usable timestamps in the container: its frame rate (or the camera's) spaces the frames
        self.timing = f"1/fps (fps = {fps:g}; the container has no usable timestamps)"
        self.dropped = 0
        return [i / fps for i in range(len(pts))]


