"""The file-backed camera: frames of a video file or an image folder, with their times.

What ``moi identify VIDEO --camera CAM.toml`` and ``moi camera-check --source``
read (``service.sources.video`` tracks the marker in them). Sources: any container
OpenCV's FFmpeg backend reads (AVI, MP4, MKV, MOV…) or a folder of images (PNG, JPEG, BMP, TIFF, PGM) taken in name order
(numbers in names compare as numbers).

Frame times: a video's come from its container (presentation timestamps,
pts × time base); the camera file's ``fps`` is not needed for them.
When they lie on the grid of the container's frame rate within its
rounding (MKV stores whole milliseconds), they are snapped to that grid:
the rounding is timing noise the camera did not have. Grid slots with no
frame are dropped frames. A folder's frames are 1/fps apart (fps from the
camera file) unless it holds ``timestamps.csv`` with columns ``file`` and
``t`` (s).

Frames come upright: a phone's video tagged to be shown turned (its display
matrix, 90°, 180° or 270°) is turned as players turn it, so the camera
file's width and height are those of the picture as shown.

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
from measurement.vision.pipeline import count_dropped

from .errors import VideoFileError

# FFmpeg reports every damaged packet on stderr; the count goes into the result instead.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

import av
import cv2  # after the log level, which FFmpeg reads when first used

# FFmpeg's messages (one per damaged packet) stay unheard: the counts go into the result instead. ``None`` keeps
# PyAV's no-op callback; any numeric level installs a Python callback that takes the GIL for every message, and
# a frame-threaded decoder freed with frames still in flight (a loop left early) logs from its worker threads
# while the main thread, holding the GIL, waits for them: a deadlock.
av.logging.set_level(None)

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm"}
TIMESTAMPS_FILE = "timestamps.csv"
#: consecutive undecodable frames after which a stream is taken to have ended
MAX_CONSECUTIVE_FAILURES = 25
#: OpenCV's turn for each counterclockwise angle of a display matrix, degrees
_TURN = {90: cv2.ROTATE_90_COUNTERCLOCKWISE, 180: cv2.ROTATE_180, 270: cv2.ROTATE_90_CLOCKWISE}


def _why(e: BaseException) -> str:
    """FFmpeg's own words for an error, without the path it repeats."""
    text = getattr(e, "strerror", None) or str(e)
    return str(text).split(":")[0].strip() or type(e).__name__


def _flush(container) -> None:
    """Each decoder finishes the frames its threads hold and lets them go (frames in flight when a loop left)."""
    for stream in container.streams.video:
        if stream.codec_context is not None and stream.codec_context.is_open:
            stream.codec_context.flush_buffers()


def _stop(container) -> None:
    """Close a video in dependency order: the decoders idle (``_flush``), then the container, which drops its
    streams (their decoders, referenced nowhere else by then, are freed first) and then frees the demuxer and
    the file. PyAV frees the demuxer's streams even while a wrapper of theirs is still referenced elsewhere, so
    nothing may hold a stream past this."""
    _flush(container)
    container.close()


def _natural_key(name: str) -> list:
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", name)]


class FrameSource:
    """Frames of a video file or an image folder as (t in s or None, grey uint8 frame or None).

    colour: yield BGR frames (uint8, h×w×3) instead of grey ones.
    After iteration: ``count`` frames offered, ``failed`` undecodable ones, ``timing`` how times
    were obtained, ``dropped`` frames missing from the stream; for a video also ``listed`` (frames the
    container lists), ``decoded``, ``codec``, ``intra_only`` (every frame coded alone, as MJPEG: rows
    repeated bit for bit are then the decoder concealing damage), ``truncated`` (why the stream
    ended early, '' if it did not) and ``rotation`` (degrees counterclockwise the frames were turned to
    come upright, from the display matrix; 0: none). ``close()`` (or ``with``) stops decoding when a loop
    leaves early.
    """

    def __init__(self, path: str | os.PathLike, config: CameraConfig, colour: bool = False):
        self.path = Path(path)
        self.config = config
        self.colour = colour
        self.count = 0
        self.failed = 0
        self.decoded = 0
        self.listed = 0
        self.codec = ""
        self.intra_only = True
        self.truncated = ""
        self.dropped = 0
        self.timing = ""
        self.rotation = 0
        self._fps = config.camera.fps
        self._frames: Iterator[tuple[float | None, np.ndarray | None]] | None = None
        if not self.path.exists():
            raise VideoFileError(f"video {str(self.path)!r} not found")

    def __iter__(self) -> Iterator[tuple[float | None, np.ndarray | None]]:
        self.close()
        self._frames = self._folder() if self.path.is_dir() else self._video()
        return self._frames

    def close(self) -> None:
        """Stop decoding now (a loop left early): the decoder and the file are closed here, not whenever the
        generator is collected. Safe twice."""
        frames, self._frames = self._frames, None
        if frames is not None:
            frames.close()  # type: ignore[attr-defined]  # a generator: runs _video's finally

    def __enter__(self) -> "FrameSource":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _need_fps(self, why: str) -> float:
        """The camera file's frame rate, which ``why`` needs (frames/s); a one-line error without it."""
        if self.config.camera.fps is None:
            raise VideoFileError(f"{str(self.path)!r}: {why}; give the frame rate as [camera] fps in the camera file")
        return self.config.camera.fps

    # -- image folder -------------------------------------------------------
    def _folder(self) -> Iterator[tuple[float | None, np.ndarray | None]]:
        files = sorted((p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES),
                       key=lambda p: _natural_key(p.name))
        if not files:
            raise VideoFileError(f"image folder {str(self.path)!r} holds no images "
                                 f"({', '.join(sorted(IMAGE_SUFFIXES))})")
        times = self._folder_times(files)
        stamped = (self.path / TIMESTAMPS_FILE).exists()
        self.timing = "timestamps.csv" if stamped else f"1/fps (fps = {self.config.camera.fps:g})"
        self.dropped = count_dropped(np.asarray(times), self.config.camera.fps) if self.config.camera.fps else 0
        for p, t in zip(files, times):
            self.count += 1
            img = cv2.imread(str(p), cv2.IMREAD_COLOR if self.colour else cv2.IMREAD_GRAYSCALE)
            if img is None:
                self.failed += 1
            else:
                self.decoded += 1
            yield t, img

    def _folder_times(self, files: list[Path]) -> list[float]:
        ts = self.path / TIMESTAMPS_FILE
        if not ts.exists():
            fps = self._need_fps(f"an image folder without {TIMESTAMPS_FILE} is timed by its frame rate")
            return [i / fps for i in range(len(files))]
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
            more = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
            raise VideoFileError(f"{ts}: no time for {missing[0]}{more}")
        return [table[p.name] for p in files]

    # -- video file -------------------------------------------------------
    def _video(self) -> Iterator[tuple[float | None, np.ndarray | None]]:
        """Decode with FFmpeg (PyAV) packet by packet; container times are yielded raw (s, from the first
        decoded frame), ``frame_times`` turns them into the trace's times afterwards."""
        if self.path.stat().st_size == 0:
            raise VideoFileError(f"video {str(self.path)!r} is empty (0 bytes)")
        try:
            container = av.open(str(self.path))
        except (av.error.FFmpegError, OSError) as e:
            raise VideoFileError(f"video {str(self.path)!r} cannot be opened ({_why(e)}); expected a video file "
                                 "FFmpeg reads (MP4, MKV, AVI, MOV…)") from None
        try:
            if not container.streams.video:
                raise VideoFileError(f"{str(self.path)!r} holds no video stream")
            self._describe(container.streams.video[0])
            # the stream is held by _decode alone: when a loop leaves early, _decode's frame is gone before
            # _stop, and the decoder is freed before the file
            yield from self._decode(container)
        finally:
            _stop(container)
        if self.decoded == 0:
            raise VideoFileError(f"video {str(self.path)!r}: no frame could be decoded ({self.listed} listed, "
                                 f"{self.failed} undecodable)")

    def _describe(self, stream) -> None:
        """What the stream says of itself: codec, frames listed, frame rate; its decoder set to FFmpeg's threads."""
        codec = stream.codec_context
        self.codec = codec.name
        # an intra-only codec (MJPEG) codes every frame alone: rows repeated bit for bit are the decoder
        # concealing damage; an inter-frame codec (H.264, HEVC) repeats unchanged regions by design
        self.intra_only = bool(codec.codec.intra_only)
        self.listed = int(stream.frames or 0)
        rate = stream.average_rate or stream.guessed_rate
        fps = float(rate) if rate else 0.0
        self._fps = fps if math.isfinite(fps) and 0 < fps < 10000 else self.config.camera.fps
        stream.thread_type = "AUTO"

    def _decode(self, container) -> Iterator[tuple[float | None, np.ndarray | None]]:
        stream = container.streams.video[0]
        time_base = float(stream.time_base) if stream.time_base else 0.0
        packets = 0
        t0: float | None = None
        first = True

        def out(frames) -> Iterator[tuple[float | None, np.ndarray | None]]:
            nonlocal t0, first
            for fr in frames:
                img = self._upright(fr.to_ndarray(format="bgr24" if self.colour else "gray"), fr.rotation)
                if first:
                    self._check_size(img)
                first = False
                t = fr.pts * time_base if fr.pts is not None and time_base else None
                if t is not None and t0 is None:
                    t0 = t
                self.count += 1
                self.decoded += 1
                yield (None if t is None or t0 is None else t - t0), img

        try:
            for packet in container.demux(stream):
                if packet.size == 0:
                    continue  # the demuxer's end-of-stream marker
                packets += 1
                try:
                    frames = packet.decode()
                except av.error.FFmpegError:
                    # a damaged packet: its slot in the stream is kept, its picture is not
                    self.count += 1
                    self.failed += 1
                    yield None, None
                    continue
                yield from out(frames)
            yield from out(stream.decode(None))  # frames the decoder still holds
        except av.error.FFmpegError as e:
            # the file ends early (truncated) or the container is damaged past this point
            self.truncated = _why(e)
        self.listed = max(self.listed, packets)

    def _upright(self, img: np.ndarray, rotation: float) -> np.ndarray:
        """The frame as it is shown: a phone stores its picture as the sensor reads it and tags the turn that
        shows it upright (the display matrix; ``rotation``: FFmpeg's counterclockwise angle, degrees). Turned as
        FFmpeg's own player turns it."""
        turn = int(round(rotation)) % 360
        if turn == 0:
            return img
        if turn % 90:
            raise VideoFileError(f"video {str(self.path)!r} is tagged to be shown turned by {rotation:g}°; "
                                 "expected a multiple of 90°")
        self.rotation = turn
        return cv2.rotate(img, _TURN[turn])

    def _check_size(self, img: np.ndarray) -> None:
        cam = self.config.camera
        if img.shape[:2] == (cam.height, cam.width):
            return
        h, w = img.shape[:2]
        stored = (h, w) if self.rotation in (90, 270) else (w, h)
        turned = (f" as shown (its display matrix turns the stored {stored[0]}×{stored[1]} picture by {self.rotation}°)"
                  if self.rotation else "")
        raise VisionError(f"video {str(self.path)!r} is {w}×{h} px{turned}; the camera file says "
                          f"{cam.width}×{cam.height}")

    def frame_times(self, pts: list[float | None]) -> list[float | None]:
        """Times (s) of the frames yielded, from their raw times (None: undecodable frame).

        Video: container times, snapped to the frame-rate grid when they are on it within the
        container's rounding; sets ``timing`` and ``dropped``. Folder: the times as read.
        """
        if self.path.is_dir():
            return pts
        fps = self._fps
        known = np.array([p for p in pts if p is not None], dtype=float)
        if known.size >= 2 and np.all(np.diff(known) > 0) and fps is None:
            # neither the container nor the camera file gives a rate: the times are the container's as they are
            self.timing = "container (no frame rate given)"
            self.dropped = max(count_dropped(known, 1.0 / float(np.median(np.diff(known)))) - self.failed, 0)
            return pts
        if known.size >= 2 and np.all(np.diff(known) > 0):
            assert fps is not None
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
        if fps is None:
            fps = self._need_fps("the container has neither usable frame times nor a frame rate")
        self.timing = f"1/fps (fps = {fps:g}; the container has no usable timestamps)"
        self.dropped = 0
        return [i / fps for i in range(len(pts))]


