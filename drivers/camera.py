"""The camera: grey frames with their timestamps, from a V4L2 device or from a simulated swing.

``Camera`` is the interface (``grab()`` → ``Frame``, ``stats()``, ``close()``,
a context manager whose ``close`` is safe twice). A camera whose frames can
be had without waiting says so with ``nonblocking = True`` and offers
``grab_ready()`` (the frames exposed by now, never waits): that is how the
mock is read on the caller's thread, so a ``ManualClock`` is never advanced
from a background thread. A blocking camera (V4L2) is read from a thread
(``drivers.camera_sensor``). Two implementations side by side, chosen in one
place (``open_camera``):

* ``V4L2Camera``: OpenCV ``CAP_V4L2``, MJPG at the camera file's resolution
  and frame rate, a small driver buffer (so a frame is at most a couple of
  periods old), kernel buffer timestamps from ``CAP_PROP_POS_MSEC``
  (CLOCK_MONOTONIC, the same clock as ``MonotonicClock``), dropped frames
  counted from the gaps between them.
* ``MockCamera``: frames rendered by ``measurement.vision.render`` (the very
  renderer the vision tests use) of the marker at the angle an angle source
  gives for the frame's time: a ``SimRig.angle`` or ``Swing.angle``. Blur,
  noise, lens distortion (from the camera file) and pose errors are options.
"""

from __future__ import annotations

import logging
import math
import os
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Callable

import cv2
import numpy as np

from measurement.flags import DROPPED_FRAMES
from measurement.vision.config import CameraConfig, CameraModel
from measurement.vision.locate import to_grey
from measurement.vision.pipeline import DropCounter
from measurement.vision.render import CameraPose, Imaging, MarkerPattern, MarkerRenderer
from measurement.vision.render_plane import PlaneRenderer, PlaneScene

from .errors import DriverConfigError, SensorFault

log = logging.getLogger("moi.drivers.camera")

#: time (s on the clock) → true swing angle (rad)
AngleSource = Callable[[float], float]



@dataclass(frozen=True, eq=False)
class Frame:
    """One grabbed frame.

    t: s, exposure time on the camera's clock. image: grey, uint8, height×width.
    index: frame number since the camera opened (counts dropped frames too, when known).
    """

    t: float
    image: np.ndarray
    index: int


class Camera(ABC):
    """A source of timestamped grey frames of the camera file's size."""

    model: CameraModel

    #: True when ``grab_ready`` is available: frames can be had without waiting, on the caller's thread
    nonblocking: bool = False

    @abstractmethod
    def grab(self) -> Frame:
        """The next frame (waits for it). Raises ``SensorFault`` when the camera stopped delivering."""

    def grab_ready(self) -> list[Frame]:
        """The frames exposed since the last grab, oldest first, without waiting (possibly none).

        Only for ``nonblocking`` cameras; raises ``SensorFault`` when the camera stopped delivering.
        """
        raise NotImplementedError(f"{type(self).__name__} blocks in grab(): read it from a thread "
                                  "(nonblocking is False)")

    @abstractmethod
    def stats(self) -> dict:
        """Counters since opening: frames delivered, dropped frames, read failures (JSON-ready)."""

    def flags(self) -> tuple[str, ...]:
        """Quality flags for a trace (``dropped_frames``)."""
        return (DROPPED_FRAMES,) if self.stats().get("dropped_frames") else ()

    @abstractmethod
    def close(self) -> None:
        """Release the device; safe twice."""

    def __enter__(self) -> "Camera":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class V4L2Camera(Camera):
    """A UVC/CSI camera through OpenCV's V4L2 backend.

    device: "/dev/video0" or an index. model: intrinsics and the image size and frame rate to ask for.
    buffer_size: driver buffers (small: a slow reader gets recent frames, and the gaps show the drops).
    max_failures: consecutive failed reads before ``SensorFault``.
    capture_factory: ``cv2.VideoCapture`` (tests pass a fake with the same methods).
    clock: fallback time source (s) when the driver gives no buffer timestamps.
    colour: deliver BGR frames (a colour target), else grey ones.
    """

    def __init__(self, device: str | int, model: CameraModel, *, buffer_size: int = 2, max_failures: int = 10,
                 capture_factory: Callable[..., Any] = cv2.VideoCapture, clock: Callable[[], float] = time.monotonic,
                 colour: bool = False):
        if not (isinstance(buffer_size, int) and 1 <= buffer_size <= 32):
            raise DriverConfigError(f"camera: buffer_size must be 1..32 buffers, got {buffer_size!r}")
        if isinstance(device, str) and device.startswith("/dev/") and not os.path.exists(device):
            raise DriverConfigError(f"camera: device {device} does not exist (is the camera plugged in? `v4l2-ctl --list-devices`)")
        rate = model.frame_rate("a V4L2 camera")
        self.model = model
        self.device = device
        self.colour = colour
        self._clock = clock
        self._max_failures = max_failures
        self._cap = capture_factory(device, cv2.CAP_V4L2)
        self._closed = False
        if not self._cap.isOpened():
            self.close()
            raise DriverConfigError(f"camera: {device} cannot be opened as a V4L2 capture device (busy, or not a camera)")
        self._cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*"MJPG"))
        self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, model.width)
        self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, model.height)
        self._cap.set(cv2.CAP_PROP_FPS, rate)
        self._cap.set(cv2.CAP_PROP_BUFFERSIZE, buffer_size)
        w, h = int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        if (w, h) != (model.width, model.height):
            self.close()
            raise DriverConfigError(f"camera: {device} delivers {w}×{h} px, the camera file says "
                                    f"{model.width}×{model.height} (a mode the camera supports is needed)")
        fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        if fps > 0 and abs(fps - rate) > 0.01 * rate:
            log.warning("camera %s runs at %g frames/s, the camera file says %g", device, fps, rate)
        self._drops = DropCounter(fps if fps > 0 else rate)
        self._index = -1
        self._frames = 0
        self._failures = 0
        self._failed_total = 0
        self._host_timestamps = 0

    def grab(self) -> Frame:
        if self._closed:
            raise SensorFault(f"camera {self.device}: grab() after close()")
        while True:
            ok, image = self._cap.read()
            if ok and image is not None:
                break
            self._failures += 1
            self._failed_total += 1
            if self._failures >= self._max_failures:
                raise SensorFault(f"camera {self.device}: {self._failures} reads in a row failed (unplugged?)")
        self._failures = 0
        ms = float(self._cap.get(cv2.CAP_PROP_POS_MSEC) or 0.0)
        if ms > 0 and math.isfinite(ms):
            t = ms / 1000.0  # kernel buffer timestamp, CLOCK_MONOTONIC
        else:
            # no buffer timestamp from this driver: the host's clock at hand-over (later by the latency)
            t = self._clock()
            self._host_timestamps += 1
        missing = self._drops.add(t)
        self._index += 1 + missing
        self._frames += 1
        return Frame(t=t, image=image if self.colour and image.ndim == 3 else to_grey(image), index=self._index)

    def stats(self) -> dict:
        return {"frames": self._frames, "dropped_frames": self._drops.dropped, "read_failures": self._failed_total,
                "host_timestamps": self._host_timestamps, "device": str(self.device)}

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                self._cap.release()
            except Exception as exc:  # pragma: no cover - a driver failing to let go must not hide the real error
                log.warning("camera %s: release failed: %s", self.device, exc)


class MockCamera(Camera):
    """Frames of the marker rendered from a simulated swing, on a fixed frame schedule of the clock.

    config: the camera file (size, fps, intrinsics, distortion, marker R and D).
    angle_source: clock time (s) → true angle (rad), e.g. ``SimRig.angle`` or
        ``lambda t: swing.angle(t - t_release)``.
    clock: a ``drivers.clock.Clock`` (``now``/``sleep``) or a bare ``() -> s`` callable.
    sleep: how to wait for the next frame when ``clock`` is a bare callable (default: no waiting,
        the frame carries its scheduled time).
    pose, imaging, pattern: the camera's yaw/pitch/roll, blur/noise/exposure, the printed marker.
    drop_probability: share of frames lost at random (tests the drop accounting); seed: noise and drops.
    buffer_size: frames ``grab_ready`` keeps for a reader that polls (older ones are dropped and
        counted, as a real camera's driver buffers overflow when the reader falls behind).

    Frame k is exposed at t0 + k/fps (t0: the clock when the camera opened). ``grab`` waits for the
    next frame; a caller that fell behind gets the newest one, and the frames it missed count as dropped.
    ``grab_ready`` never waits: it renders the frames exposed by now (at most ``buffer_size``), on the
    caller's thread, so a ``ManualClock`` only moves when the test moves it.
    """

    nonblocking = True

    def __init__(self, config: CameraConfig, angle_source: AngleSource, clock: Any, *,
                 sleep: Callable[[float], None] | None = None, pose: CameraPose = CameraPose(),
                 imaging: Imaging = Imaging(), pattern: MarkerPattern = MarkerPattern(),
                 drop_probability: float = 0.0, seed: int | None = None, buffer_size: int = 8):
        if not (0.0 <= drop_probability < 1.0):
            raise DriverConfigError(f"mock camera: drop_probability must be in [0, 1), got {drop_probability!r}")
        if not (isinstance(buffer_size, int) and not isinstance(buffer_size, bool) and 1 <= buffer_size <= 1000):
            raise DriverConfigError(f"mock camera: buffer_size must be 1..1000 frames, got {buffer_size!r}")
        self.model = config.camera
        self.config = config
        self._angle = angle_source
        if hasattr(clock, "now"):
            self._now: Callable[[], float] = clock.now
            self._sleep = sleep or getattr(clock, "sleep", None)
        elif callable(clock):
            self._now, self._sleep = clock, sleep
        else:
            raise DriverConfigError(f"mock camera: clock must be a Clock or a callable returning s, got {clock!r}")
        self.renderer: MarkerRenderer | PlaneRenderer
        if config.edge:
            self.renderer = MarkerRenderer(config.camera, config.cylinder, pattern=pattern, pose=pose,
                                           imaging=imaging, seed=seed)
        else:
            # the camera file's target, drawn on a pendulum (face-on) or a platform (along the axis)
            cam = config.camera
            self.renderer = PlaneRenderer(cam.width, cam.height, config.target,
                                          PlaneScene.for_view(cam.width, cam.height, config.target),
                                          imaging=imaging, seed=0 if seed is None else seed)
        self._rng = np.random.default_rng(None if seed is None else seed + 1)
        self._drop_p = float(drop_probability)
        self._buffer = buffer_size
        self._period = 1.0 / config.camera.frame_rate("the mock camera")
        self._t0 = float(self._now())
        self._next = 0
        self._frames = 0
        self._dropped = 0
        self._closed = False

    def grab(self) -> Frame:
        if self._closed:
            raise SensorFault("mock camera: grab() after close()")
        while True:
            now = float(self._now())
            due = self._t0 + self._next * self._period
            if due > now and self._sleep is not None:
                self._sleep(due - now)
            elif due + self._period <= now:
                # the reader fell behind: the frames in between are gone, as with a real camera
                newest = int(math.floor((now - self._t0) / self._period + 1e-9))
                self._dropped += newest - self._next
                self._next = newest
                due = self._t0 + self._next * self._period
            k = self._next
            self._next += 1
            if self._drop_p and self._rng.random() < self._drop_p:
                self._dropped += 1
                continue
            self._frames += 1
            return Frame(t=due, image=self.renderer.render_at(self._angle, due), index=k)

    def grab_ready(self) -> list[Frame]:
        if self._closed:
            raise SensorFault("mock camera: grab_ready() after close()")
        # index of the newest frame exposed by now (the epsilon: a clock landing exactly on a frame time)
        newest = int(math.floor((float(self._now()) - self._t0) / self._period + 1e-9))
        if newest < self._next:
            return []
        first = max(self._next, newest - self._buffer + 1)
        self._dropped += first - self._next  # overwritten in the buffers before anyone read them
        self._next = newest + 1
        frames = []
        for k in range(first, newest + 1):
            if self._drop_p and self._rng.random() < self._drop_p:
                self._dropped += 1
                continue
            due = self._t0 + k * self._period
            self._frames += 1
            frames.append(Frame(t=due, image=self.renderer.render_at(self._angle, due), index=k))
        return frames

    def stats(self) -> dict:
        return {"frames": self._frames, "dropped_frames": self._dropped, "read_failures": 0, "device": "mock"}

    def close(self) -> None:
        self._closed = True


def open_camera(config: CameraConfig, device: str | int | None = None, *, angle_source: AngleSource | None = None,
                clock: Any = None, **mock_options: Any) -> Camera:
    """The one place that picks the camera: the V4L2 ``device`` when given, else a mock of the swing.

    Without a device, ``angle_source`` (default: the marker held at rest) and ``clock`` (default:
    ``time.monotonic``) drive a ``MockCamera``; ``mock_options`` go to it.
    """
    if device is not None:
        if mock_options:
            raise DriverConfigError(f"camera: {sorted(mock_options)} apply only to the mock camera")
        return V4L2Camera(device, config.camera, colour=config.target.needs_colour)
    return MockCamera(config, angle_source or (lambda t: 0.0), clock or time.monotonic, **mock_options)
