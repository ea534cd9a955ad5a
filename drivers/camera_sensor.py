"""The camera as an angle sensor: frames tracked as they arrive, the camera yaw fitted over the whole swing.

``CameraAngleSensor`` is an ``AngleSensor`` (source "camera") over any
``drivers.camera.Camera`` and the camera file (intrinsics, marker geometry,
pose settings). The sequencer captures from it exactly as from the encoder.

How frames reach the tracker depends on the camera, decided here and nowhere else:

* a ``nonblocking`` camera (``MockCamera``) is read inside ``read()``, on the
  caller's thread: the frames exposed by now on the clock are rendered and
  tracked there. No thread ever sleeps on the clock, so a capture on a
  ``ManualClock`` is exactly reproducible and costs no wall time.
* a blocking camera (``V4L2Camera``) is read by a reader thread between
  ``start()`` and ``stop()``: it grabs, tracks and buffers; ``read()`` only
  drains the buffer and never blocks.

Each frame becomes a sample at the frame's exposure time (s on the camera's
clock: CLOCK_MONOTONIC for V4L2, the injected clock for the mock; the same
clock the sequencer runs on) with the angle of the exact cylinder geometry
at the configured yaw (default 0). A frame without the marker (``marker_lost``)
or unusable (``corrupt_frame``) leaves a gap; frames missing from the
camera's numbering are ``dropped_frames``; all three are counted and flagged,
never fatal, until the marker has not been seen for ``max_lost_time`` s of
frames in a row: then ``SensorFault`` with the counts and the last reason.

The camera's yaw needs the whole swing: ``finish(trace)``, which the
sequencer calls once after the capture (see ``firmware_host``), fits it
(``measurement.vision.pose``), recomputes the angles with it and returns the
trace with ``meta["camera"]`` (yaw ± σ, counts, edge quality) and the flag
``camera_pose`` when |yaw| exceeds the camera file's limit.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import replace
from typing import Any

import numpy as np

from measurement.trace import Trace
from measurement.vision.body import provisional_angle
from measurement.vision.config import CameraConfig
from measurement.vision.geometry import angle_from_normalised
from measurement.vision.locate import CORRUPT, LOST, TrackerSettings
from measurement.vision.locators import PointObservation
from measurement.vision.pipeline import DROPPED, Tracking, VisionSettings, trace_from_tracking, tracker_for

from .camera import Camera, Frame
from .clock import Clock, MonotonicClock
from .errors import DriverConfigError, SensorFault
from .sensor import SampleBuffer

log = logging.getLogger("moi.drivers.camera_sensor")


class CameraAngleSensor:
    """A ``Camera`` and the camera file as an ``AngleSensor`` (source "camera").

    camera: any ``Camera``; the sensor owns it (``close`` closes it).
    config: the camera file (``CameraConfig``): intrinsics, marker radius/distance, pose settings.
    clock: the sequencer's clock (s); frames exposed before ``start()`` on it are never returned.
    tracker: marker tracker settings. vision: yaw estimation and limit (default: from ``config.pose``).
    max_lost_time: s of consecutive frames without the marker (lost or corrupt) that make a
        ``SensorFault``; at least 5 frames.
    stop_timeout: real s ``stop()`` waits for the reader thread to finish the frame in hand.
    """

    source = "camera"

    def __init__(self, camera: Camera, config: CameraConfig, clock: Clock | None = None, *,
                 tracker: TrackerSettings = TrackerSettings(), vision: VisionSettings | None = None,
                 max_lost_time: float = 0.5, stop_timeout: float = 2.0):
        if not isinstance(camera, Camera):
            raise DriverConfigError(f"camera sensor: camera must be a drivers.camera.Camera, got {camera!r}")
        if not isinstance(config, CameraConfig):
            raise DriverConfigError(f"camera sensor: config must be a CameraConfig (the camera file), got {config!r}")
        if (camera.model.width, camera.model.height) != (config.camera.width, config.camera.height):
            raise DriverConfigError(
                f"camera sensor: the camera delivers {camera.model.width}×{camera.model.height} px, the camera "
                f"file says {config.camera.width}×{config.camera.height}")
        if not (isinstance(max_lost_time, (int, float)) and math.isfinite(max_lost_time) and max_lost_time > 0):
            raise DriverConfigError(f"camera sensor: max_lost_time must be a time > 0 s, got {max_lost_time!r}")
        if not (isinstance(stop_timeout, (int, float)) and stop_timeout > 0):
            raise DriverConfigError(f"camera sensor: stop_timeout must be a time > 0 s, got {stop_timeout!r}")
        self.camera = camera
        self.config = config
        self.clock = clock or MonotonicClock()
        self.tracker_settings = tracker
        self.vision = vision or VisionSettings.from_config(config)
        self.fps = config.camera.frame_rate("a live camera")
        self.max_lost_frames = max(5, int(math.ceil(max_lost_time * self.fps)))
        self._stop_timeout = float(stop_timeout)
        # the camera counts from opening: only the frames of the current capture are this capture's
        self._threaded = not camera.nonblocking
        self._buffer = SampleBuffer()
        self._lock = self._buffer.lock  # also guards the counters
        self._thread: threading.Thread | None = None
        self._stop_reading = threading.Event()
        self._capturing = False
        self._closed = False
        self._tracker = tracker_for(config, tracker)
        self._reset(math.inf)

    def use_camera_file(self, config: CameraConfig) -> None:
        """The camera file read again (a new region of interest): the next capture's tracker is built from it.
        Between captures; the frame size stays the camera's (DriverConfigError otherwise)."""
        if not isinstance(config, CameraConfig):
            raise DriverConfigError(f"camera sensor: config must be a CameraConfig (the camera file), got {config!r}")
        model = self.camera.model
        if (model.width, model.height) != (config.camera.width, config.camera.height):
            raise DriverConfigError(f"camera sensor: the camera delivers {model.width}×{model.height} px, the camera "
                                    f"file now says {config.camera.width}×{config.camera.height}")
        with self._lock:
            self.config = config

    # -- AngleSensor ---------------------------------------------------------------
    def start(self) -> None:
        """Begin a capture: counters reset, a fresh tracker lock, frames from now on."""
        if self._closed:
            raise SensorFault("camera fault: start() after close()")
        self.stop()
        if self._thread is not None and self._thread.is_alive():
            raise SensorFault("camera fault: the previous capture's reader is still blocked in grab() "
                              "(camera not delivering frames?)")
        with self._lock:
            self._reset(float(self.clock.now()))
            self._tracker = tracker_for(self.config, self.tracker_settings)
            self._capturing = True
        if self._threaded:
            self._stop_reading = threading.Event()
            self._thread = threading.Thread(target=self._reader, args=(self._stop_reading,),
                                            name="moi-camera-reader", daemon=True)
            self._thread.start()

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """Samples since the last read: (t in s on the clock, angle in rad). Raises ``SensorFault`` after a fault.

        With a nonblocking camera the frames exposed by now are grabbed and tracked here.
        """
        if not self._threaded and self._capturing and self._buffer.fault is None:
            try:
                frames = self.camera.grab_ready()
            except SensorFault as exc:
                self._set_fault(exc)
            else:
                for frame in frames:
                    if not self._process(frame):
                        break
        return self._buffer.drain()

    def stop(self) -> None:
        """Stop grabbing (safe when not started, and twice); samples already taken stay readable."""
        self._capturing = False
        thread = self._thread
        if thread is not None:
            self._stop_reading.set()
            if thread is not threading.current_thread():
                thread.join(self._stop_timeout)
            if thread.is_alive():
                log.warning("camera reader still blocked in grab() %g s after stop()", self._stop_timeout)
            else:
                self._thread = None

    def stats(self) -> dict:
        """Counters of the current/last capture (JSON-ready): frames, samples, lost/corrupt/dropped, rate."""
        with self._lock:
            c = {"frames": self._tracking.frames, "samples": self._buffer.count,
                 "marker_lost": self._tracking.lost, "corrupt_frames": self._tracking.corrupt,
                 "dropped_frames": self._dropped, "max_run_without_marker": self._max_run,
                 "frames_before_start": self._early, "failures": dict(self._tracking.reasons),
                 "fps": self.fps, "reader": "thread" if self._threaded else "poll"}
            rate = self._buffer.rate()
            if rate is not None:
                c["rate_hz"] = rate
        c["device"] = str(self.camera.stats().get("device", type(self.camera).__name__))
        return c

    def flags(self) -> tuple[str, ...]:
        """``marker_lost``, ``corrupt_frame``, ``dropped_frames`` of the current/last capture."""
        with self._lock:
            return tuple(flag for flag, n in ((LOST, self._tracking.lost), (CORRUPT, self._tracking.corrupt),
                                              (DROPPED, self._dropped)) if n)

    def wait_for_samples(self, n: int, timeout: float) -> bool:
        """Block until ``n`` samples were taken since ``start()`` (True), a fault, or ``timeout`` s of real time (False).

        For a threaded (blocking) camera; a nonblocking one only takes samples inside ``read()``.
        """
        return self._buffer.wait_for(n, timeout)

    def finish(self, trace: Trace) -> Trace:
        """The captured ``trace`` (t in s, angle in rad) with the camera yaw fitted and corrected.

        Called once per capture by the sequencer, after ``stop()``, before identification. The
        marker positions tracked for the trace's samples (image coordinates, kept by the tracking
        step) are fitted for the yaw over the whole swing and turned into angles with it. Returns a new
        trace: same source, ``meta`` with ``meta["camera"]`` extended by the pose and edge figures,
        flags plus ``camera_pose`` when |yaw| > the limit. Raises ``VisionError`` (a
        ``MeasurementError``) when too few samples are left.
        """
        with self._lock:
            live = self._tracking
            # the sequencer's trace counts time from its first kept sample (meta "sequencer.t0", clock
            # time in s), which need not be the first tracked frame: the sequencer may not keep every sample
            first = live.t[0] if live.t else 0.0
            origin = float((trace.meta.get("sequencer") or {}).get("t0", first))
            t_rel = np.asarray(live.t, dtype=float) - origin
            keep = np.isin(t_rel, trace.t)
            tracking = live.subset(keep)
            tracking.t = t_rel[keep].tolist()
            if tracking.t:
                # the frames of the kept record, on its time axis: what the tracked share is judged against
                seen = np.asarray(live.seen_times, dtype=float) - origin
                span = (seen >= tracking.t[0] - 1e-9) & (seen <= tracking.t[-1] + 1e-9)
                tracking.seen_times = seen[span].tolist()
            dropped = self._dropped
        fitted = trace_from_tracking(tracking, self.config, source=trace.source, settings=self.vision,
                                     dropped=dropped)
        meta = dict(trace.meta)
        camera_meta = dict(meta.get(self.source) or {})
        camera_meta.update(fitted.meta.get("camera", {}))
        meta[self.source] = camera_meta
        meta.setdefault("sensor", "camera")
        flags = tuple(dict.fromkeys((*trace.flags, *fitted.flags)))
        return Trace(fitted.t, fitted.angle, source=trace.source, flags=flags, meta=meta)

    def close(self) -> None:
        """Stop and close the camera; safe twice."""
        if self._closed:
            return
        self._closed = True
        self.stop()
        self.camera.close()

    def __enter__(self) -> "CameraAngleSensor":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- internals -----------------------------------------------------------------
    def _reset(self, t_start: float) -> None:
        self._t_start = t_start
        self._buffer.reset()
        self._tracking = Tracking()  # only the counters and the edge figures: times/angles go to the buffer
        self._dropped = 0
        self._early = 0
        self._pivot = self.config.target.pivot
        self._run = 0
        self._max_run = 0
        self._last_index: int | None = None

    def _set_fault(self, fault: SensorFault) -> None:
        if self._buffer.fail(fault):
            log.error("%s", fault)
        self._capturing = False

    def _process(self, frame: Frame) -> bool:
        """Track one frame into the buffer and counters; False once the capture is faulted."""
        if frame.t < self._t_start:
            with self._lock:
                self._early += 1  # exposed before start(): a driver buffer's stale frame
            return True
        obs = self._tracker.locate(frame.image)
        theta = math.nan
        if isinstance(obs, PointObservation):
            # the live angle of a body vector (a single blob's pivot may be known only after the swing:
            # ``finish`` measures it, the view and the quality over the whole record)
            if self._pivot is None and obs.found and obs.a is None and obs.b is not None:
                # until the arc is known: a pivot ten image heights above the first sighting
                self._pivot = (obs.b[0], obs.b[1] - 10.0 * self.config.camera.height)
            theta = provisional_angle(obs, self._pivot)
        elif obs.found:
            theta = float(angle_from_normalised(obs.x, self.config.cylinder, self.vision.yaw, 0.0))
            if not math.isfinite(theta):
                obs = replace(obs, found=False, reason=LOST,
                              detail="beyond the cylinder's silhouette (check radius and distance in the camera file)")
        with self._lock:
            track = self._tracking
            if self._last_index is not None and frame.index > self._last_index + 1:
                self._dropped += frame.index - self._last_index - 1
            self._last_index = frame.index
            if track.add(frame.t, obs):  # the tracking step of measurement.vision.pipeline, shared with files
                self._buffer.add(frame.t, theta)
                self._run = 0
                return True
            detail, reason = ("timestamp out of order", CORRUPT) if obs.found else (obs.detail, obs.reason)
            self._run += 1
            self._max_run = max(self._max_run, self._run)
            if self._run < self.max_lost_frames:
                return True
            fault = SensorFault(
                f"camera fault: no marker in {self._run} frames in a row ({self._run / self.fps:.2g} s at "
                f"{self.fps:g} frames/s); last: {detail or reason}; lost {track.lost}, corrupt {track.corrupt} of "
                f"{track.frames} frames (is the marker in view and lit? check with `moi camera-check`)")
        self._set_fault(fault)
        return False

    def _reader(self, stop: threading.Event) -> None:
        """Reader thread of a blocking camera: grab, track, buffer until ``stop`` is set or a fault."""
        while not stop.is_set():
            try:
                frame = self.camera.grab()
            except SensorFault as exc:
                if not stop.is_set():
                    self._set_fault(exc)
                return
            except Exception as exc:  # top of the thread: an unforeseen camera error must surface as a fault
                log.exception("camera reader stopped")
                if not stop.is_set():
                    self._set_fault(SensorFault(f"camera fault: grab() failed: {type(exc).__name__}: {exc}"))
                return
            if stop.is_set():
                return  # grabbed after stop(): not this capture's
            if not self._process(frame):
                return
