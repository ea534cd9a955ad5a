"""drivers.camera_sensor: the camera as an AngleSensor.

Polled path: a MockCamera filming the simulated rig on a ManualClock (the
sensor renders and tracks inside read(), the clock moves only when the test
moves it). Threaded path: a V4L2Camera over a fake capture device that hands
out rendered frames with kernel timestamps and then blocks, as a camera
waiting for its next frame does. No wall-clock sleeps.
"""

from __future__ import annotations

import math
import threading

import cv2
import numpy as np
import pytest

from drivers.camera import Frame, MockCamera, V4L2Camera
from drivers.camera_sensor import CameraAngleSensor
from drivers.clock import ManualClock
from drivers.errors import DriverConfigError, SensorFault
from drivers.sensor import AngleSensor
from drivers.simrig import SimRig
from measurement import Pendulum, Rig, Trace
from measurement.vision import CameraConfig, CameraModel, CameraPose, Imaging, MarkerGeometry, MarkerRenderer

FPS = 100.0
CAMERA = CameraModel(width=640, height=480, fps=FPS, fx=600.0, fy=600.0, cx=319.5, cy=239.5)
MARKER = MarkerGeometry(radius=0.10, distance=0.25)
CONFIG = CameraConfig(camera=CAMERA, marker=MARKER)
IMAGING = Imaging(blur=1.0, noise=2.0)
RIG = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
TRUTH = Pendulum(RIG, 0.0125, {"viscous": {"c": 1.5e-4}})
TOL = math.radians(0.01)  # rad: the tracker's accuracy budget


def make(clock, *, camera_cls=MockCamera, yaw_deg=0.0, config=CONFIG, theta0=0.2, **options):
    rig = SimRig(TRUTH, theta0=theta0, clock=clock, duration=30.0)
    cam = camera_cls(config, rig.angle, clock, imaging=IMAGING, seed=7, pose=CameraPose(yaw=math.radians(yaw_deg)))
    return rig, CameraAngleSensor(cam, config, clock, **options)


def capture(sensor, clock, seconds, dt=0.01):
    """Poll like the sequencer: advance dt, read; returns all (t, angle)."""
    ts, angles = [], []
    for _ in range(int(round(seconds / dt))):
        clock.advance(dt)
        t, a = sensor.read()
        ts.extend(t.tolist())
        angles.extend(a.tolist())
    return np.asarray(ts), np.asarray(angles)


class Glitching(MockCamera):
    """A mock camera whose chosen frames come out blank (marker lost) or of the wrong size (corrupt)."""

    blank_from = math.inf   # s: every frame from then on is blank (the lens covered)

    def __init__(self, *args, blank=(), corrupt=(), **kwargs):
        super().__init__(*args, **kwargs)
        self.blank, self.corrupt = set(blank), set(corrupt)

    def grab_ready(self):
        out = []
        for f in super().grab_ready():
            if f.index in self.blank or f.t >= self.blank_from:
                f = Frame(f.t, np.full_like(f.image, 90), f.index)
            elif f.index in self.corrupt:
                f = Frame(f.t, f.image[:240], f.index)
            out.append(f)
        return out


def test_it_is_an_angle_sensor_and_samples_in_order_on_the_frame_schedule():
    clock = ManualClock(start=100.0)
    rig, sensor = make(clock)
    with sensor:
        assert isinstance(sensor, AngleSensor) and sensor.source == "camera"
        clock.advance(0.505)      # the camera runs before the capture: those frames are never returned
        sensor.start()
        t_start = clock.now()
        rig.release()
        t, a = capture(sensor, clock, 1.0)
        assert clock.now() == pytest.approx(t_start + 1.0, abs=1e-9)  # only the test moved the clock
        assert t.size == 100 and np.all(np.diff(t) > 0)
        assert t[0] >= t_start and t[-1] <= clock.now()
        assert np.allclose(np.diff(t), 1 / FPS)                          # the camera's frame grid
        truth = np.array([rig.angle(x) for x in t])
        assert np.max(np.abs(a - truth)) < TOL                           # the exact geometry, straight camera
        assert a.min() < 0 < a.max()                                     # it swung
        s = sensor.stats()
        assert (s["frames"], s["samples"], s["marker_lost"], s["corrupt_frames"], s["dropped_frames"]) == (100, 100, 0, 0, 0)
        assert s["rate_hz"] == pytest.approx(FPS) and s["reader"] == "poll" and sensor.flags() == ()
        assert s["frames_before_start"] == 7  # of the mock's 8 buffers at the first read, 7 predate start()

        # coarser polling gets several frames per read, still every one of them
        t2, _ = capture(sensor, clock, 0.12, dt=0.04)
        assert t2.size == 12 and t2[0] == pytest.approx(t[-1] + 1 / FPS)

        sensor.stop()
        clock.advance(0.2)
        t3, _ = sensor.read()
        assert t3.size == 0  # stopped: nothing grabbed any more

        sensor.start()       # a new capture starts from scratch
        assert sensor.stats()["samples"] == 0
        t4, _ = capture(sensor, clock, 0.05)
        assert t4.size == 5 and t4[0] >= clock.now() - 0.05


def test_lost_and_corrupt_frames_leave_gaps_counts_and_flags_but_no_fault():
    clock = ManualClock()
    rig, sensor = make(clock, camera_cls=Glitching)
    sensor.camera.blank = {10, 11, 12, 40}
    sensor.camera.corrupt = {20, 21}
    with sensor:
        clock.advance(0.005)   # half a frame: the capture holds frames 1, 2, ...
        sensor.start()
        rig.release()
        t, a = capture(sensor, clock, 0.6)
        k = np.rint(t * FPS).astype(int)    # frame numbers of the samples (camera opened at 0)
        assert set(range(1, 61)) - set(k.tolist()) == {10, 11, 12, 40, 20, 21}
        s = sensor.stats()
        assert (s["frames"], s["samples"], s["marker_lost"], s["corrupt_frames"]) == (60, 54, 4, 2)
        assert s["max_run_without_marker"] == 3 and s["dropped_frames"] == 0
        assert set(sensor.flags()) == {"marker_lost", "corrupt_frame"}
        assert sum(s["failures"].values()) == 6
        truth = np.array([rig.angle(x) for x in t])
        assert np.max(np.abs(a - truth)) < TOL  # the tracker re-locked after each gap


def test_frames_a_slow_reader_missed_are_counted_as_dropped():
    clock = ManualClock()
    rig, sensor = make(clock)
    with sensor:
        clock.advance(0.005)
        sensor.start()
        capture(sensor, clock, 0.1)
        clock.advance(0.2)       # the reader stalls for 20 frames; the camera buffers only 8
        t, _ = sensor.read()
        assert t.size == 8
        s = sensor.stats()
        assert s["dropped_frames"] == 12 and s["samples"] == 18 and sensor.flags() == ("dropped_frames",)


def test_a_long_run_without_the_marker_is_a_sensor_fault_with_the_reason():
    clock = ManualClock()
    rig, sensor = make(clock, camera_cls=Glitching, max_lost_time=0.3)
    sensor.camera.blank_from = 0.5
    with sensor:
        clock.advance(0.005)
        sensor.start()
        rig.release()
        t, _ = capture(sensor, clock, 0.5)
        assert t.size == 49
        with pytest.raises(SensorFault, match=r"no marker in 30 frames in a row \(0.3 s at 100 frames/s\)") as err:
            capture(sensor, clock, 0.5)
        assert "lost 30, corrupt 0" in str(err.value) and "moi camera-check" in str(err.value)
        with pytest.raises(SensorFault):  # stays faulted until the next start()
            sensor.read()
        assert sensor.stats()["max_run_without_marker"] == 30
        sensor.start()
        sensor.camera.blank_from = math.inf
        t, _ = capture(sensor, clock, 0.1)
        assert t.size == 10


def test_a_camera_that_stops_delivering_raises_its_fault_from_read():
    class Unplugged(MockCamera):
        def grab_ready(self):
            raise SensorFault("mock camera: unplugged")

    clock = ManualClock()
    _, sensor = make(clock, camera_cls=Unplugged)
    with sensor:
        sensor.start()
        clock.advance(0.01)
        with pytest.raises(SensorFault, match="unplugged"):
            sensor.read()


def test_finish_fits_the_yaw_over_the_swing_and_corrects_the_angles():
    config = CameraConfig(camera=CameraModel(width=640, height=480, fps=30.0, fx=600.0, fy=600.0, cx=319.5,
                                             cy=239.5), marker=MARKER)
    clock = ManualClock()
    rig, sensor = make(clock, yaw_deg=4.0, config=config)
    with sensor:
        sensor.start()
        held = capture(sensor, clock, 0.3, dt=1 / 30)  # at the release angle
        rig.release()
        swing = capture(sensor, clock, 5.5, dt=1 / 30)
        sensor.stop()
        t, a = np.concatenate([held[0], swing[0]]), np.concatenate([held[1], swing[1]])
        t0 = t[0]
        raw = Trace(t - t0, a, source="camera", flags=sensor.flags(),
                    meta={"camera": sensor.stats(), "sequencer": {"release_t": 0.3}})
        truth = np.array([rig.angle(x) for x in t])
        assert np.ptp(a - truth) > 20 * TOL     # uncorrected: a yawed camera's angles are off

        done = sensor.finish(raw)
        cam = done.meta["camera"]
        assert cam["yaw_deg"] == pytest.approx(4.0, abs=0.05) and cam["yaw_corrected"] is True
        assert cam["frames"] == cam["frames_used"] == t.size and cam["reader"] == "poll"  # stats kept, pose added
        assert "camera_pose" in done.flags and done.meta["sequencer"] == {"release_t": 0.3}
        assert done.source == "camera" and np.array_equal(done.t, raw.t)
        err = done.angle - truth
        assert np.ptp(err - np.mean(err)) < 2 * TOL  # corrected, up to the zero (which identification fits)

        # too short a record to tell the yaw: not estimated, angles unchanged, said so
        short = Trace(raw.t[:30], raw.angle[:30], source="camera", meta={"camera": {}})
        left = sensor.finish(short)
        assert left.meta["camera"]["yaw_estimated"] is False and "pose_note" in left.meta["camera"]
        assert np.allclose(left.angle, short.angle, atol=1e-12, rtol=0) and "camera_pose" not in left.flags


# -- the threaded path: a blocking V4L2 camera ----------------------------------------------------------
class StreamingCapture:
    """cv2.VideoCapture's surface: the given frames (kernel timestamps in ms), then it waits for ``end``
    (a camera between frames) and fails every read after it (unplugged)."""

    def __init__(self, frames):
        self.frames = list(frames)
        self.end = threading.Event()
        self.pos = 0.0
        self.props = {}

    def __call__(self, *args):
        return self

    def isOpened(self):
        return True

    def set(self, prop, value):
        self.props[prop] = value
        return True

    def get(self, prop):
        return {cv2.CAP_PROP_FRAME_WIDTH: 640, cv2.CAP_PROP_FRAME_HEIGHT: 480, cv2.CAP_PROP_FPS: FPS,
                cv2.CAP_PROP_POS_MSEC: self.pos}.get(prop, 0.0)

    def read(self):
        if self.frames:
            self.pos, image = self.frames.pop(0)
            return True, image
        self.end.wait(10.0)
        return False, None

    def release(self):
        self.end.set()


def test_a_blocking_camera_is_read_by_a_thread_and_its_fault_surfaces_in_read():
    renderer = MarkerRenderer(CAMERA, MARKER, imaging=IMAGING, seed=3)
    angle = lambda t: 0.15 * math.sin(5.4 * (t - 10.0))  # noqa: E731
    stamps = [9.98, 9.99] + [10.0 + k / FPS for k in (0, 1, 2, 3, 5, 6, 7, 8, 9, 10)]  # 2 stale, frame 4 lost
    fake = StreamingCapture([(s * 1000.0, renderer.render(angle(s))) for s in stamps])
    clock = ManualClock(start=10.0)   # the sequencer's clock: CLOCK_MONOTONIC on the device
    cam = V4L2Camera(0, CAMERA, capture_factory=fake, max_failures=3)
    sensor = CameraAngleSensor(cam, CONFIG, clock)
    try:
        assert not cam.nonblocking
        sensor.start()
        assert sensor.wait_for_samples(10, timeout=10.0)
        t, a = sensor.read()
        assert t == pytest.approx([10.0 + k / FPS for k in (0, 1, 2, 3, 5, 6, 7, 8, 9, 10)])
        assert np.max(np.abs(a - [angle(x) for x in t])) < TOL
        s = sensor.stats()
        assert s["reader"] == "thread" and s["frames_before_start"] == 2 and s["dropped_frames"] == 1
        assert sensor.flags() == ("dropped_frames",)

        fake.end.set()   # the camera is unplugged: V4L2Camera gives up after 3 failed reads
        assert not sensor.wait_for_samples(11, timeout=10.0)
        with pytest.raises(SensorFault, match="3 reads in a row failed"):
            sensor.read()
    finally:
        sensor.close()
        sensor.close()
    with pytest.raises(SensorFault, match="after close"):
        sensor.start()


def test_settings_are_checked():
    clock = ManualClock()
    cam = MockCamera(CONFIG, lambda t: 0.0, clock)
    with pytest.raises(DriverConfigError, match="max_lost_time"):
        CameraAngleSensor(cam, CONFIG, clock, max_lost_time=0)
    small = CameraConfig(camera=CameraModel(width=320, height=240, fps=FPS, fx=300.0, fy=300.0, cx=159.5,
                                            cy=119.5), marker=MARKER)
    with pytest.raises(DriverConfigError, match="640×480 px, the camera file says 320×240"):
        CameraAngleSensor(cam, small, clock)
    with pytest.raises(DriverConfigError, match="Camera"):
        CameraAngleSensor(object(), CONFIG, clock)  # type: ignore[arg-type]
    with V4L2Camera(0, CAMERA, capture_factory=StreamingCapture([])) as v4l2, \
            pytest.raises(NotImplementedError, match="read it from a thread"):
        v4l2.grab_ready()


def test_a_tag_target_is_tracked_live_with_the_rules_of_a_video():
    """The live path takes the camera file's target (here a printed tag on a face-on pendulum, rendered by the
    mock) and the same quality rules as a video: a record where the tag is missing from half the frames is refused."""
    from measurement.errors import VisionError

    config = CameraConfig.from_dict({"camera": {"width": 320, "height": 240, "fps": 30.0}, "target": {"kind": "tag"}})
    clock = ManualClock()
    rig = SimRig(TRUTH, theta0=0.2, clock=clock, duration=30.0)
    cam = Glitching(config, rig.angle, clock, imaging=IMAGING, seed=7)
    with CameraAngleSensor(cam, config, clock) as sensor:
        sensor.start()
        rig.release()
        t, a = capture(sensor, clock, 4.0, dt=1 / 30)
        sensor.stop()
        done = sensor.finish(Trace(t - t[0], a, source="camera", meta={"camera": sensor.stats()}))
        truth = np.array([rig.angle(x) for x in t])
        err = done.angle - truth[np.isin(t - t[0], done.t)]
        assert np.ptp(err - np.mean(err)) < math.radians(0.5)
        cam_meta = done.meta["camera"]
        assert cam_meta["target"]["kind"] == "tag" and cam_meta["tracking"]["tracked_share"] == 1.0

        cam.blank = set(range(0, 100_000, 2))  # every other frame without the tag: never long enough for a fault
        sensor.start()
        t, a = capture(sensor, clock, 2.5, dt=1 / 30)
        sensor.stop()
        with pytest.raises(VisionError, match="tracked in"):
            sensor.finish(Trace(t - t[0], a, source="camera", meta={"camera": sensor.stats()}))


def test_a_camera_file_read_again_is_used_from_the_next_capture_and_must_keep_the_frame_size():
    import dataclasses

    clock = ManualClock()
    _rig, sensor = make(clock)
    with sensor:
        roi = (40, 140, 600, 480)
        new = dataclasses.replace(CONFIG, target=dataclasses.replace(CONFIG.target, roi=roi))
        sensor.use_camera_file(new)
        sensor.start()
        assert sensor.config is new and sensor._tracker.settings.roi == roi  # the capture tracks in it
        sensor.stop()
        smaller = dataclasses.replace(CONFIG, camera=dataclasses.replace(CAMERA, width=320, height=240, cx=159.5,
                                                                         cy=119.5))
        with pytest.raises(DriverConfigError, match="delivers 640×480 px, the camera file now says 320×240"):
            sensor.use_camera_file(smaller)
        assert sensor.config is new
