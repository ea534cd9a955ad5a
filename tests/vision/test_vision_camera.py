"""drivers.camera: the mock camera driven by the simulated rig, and the V4L2 camera against a fake capture."""

import math

import cv2
import numpy as np
import pytest

from drivers.camera import Camera, MockCamera, V4L2Camera, open_camera
from drivers.clock import ManualClock
from drivers.errors import DriverConfigError, SensorFault
from drivers.simrig import SimRig
from measurement import Pendulum
from measurement.vision import MarkerTracker, angle_from_normalised, trace_from_tracking, track_frames

from .conftest import CAMERA, CONFIG, IMAGING, J_TRUE, MARKER, RIG, VISCOUS_C

TOL = math.radians(0.01)


def measured_angle(tracker, frame):
    obs = tracker.locate(frame.image)
    assert obs.found
    return angle_from_normalised(obs.x, MARKER)


def test_mock_camera_films_the_simulated_rig_on_the_shared_clock():
    clock = ManualClock(start=100.0)
    rig = SimRig(Pendulum(RIG, J_TRUE, {"viscous": {"c": VISCOUS_C}}), theta0=0.2, clock=clock, duration=10.0)
    tracker = MarkerTracker(CAMERA)
    with MockCamera(CONFIG, rig.angle, clock, imaging=IMAGING, seed=1) as cam:
        held = [cam.grab() for _ in range(6)]
        assert [f.index for f in held] == list(range(6))
        assert np.allclose([f.t for f in held], 100.0 + np.arange(6) / 60.0)
        assert held[0].image.shape == (480, 640) and held[0].image.dtype == np.uint8
        assert measured_angle(tracker, held[-1]) == pytest.approx(0.2, abs=TOL)
        rig.release()
        frames = [cam.grab() for _ in range(90)]
        assert clock.now() == pytest.approx(frames[-1].t)  # grab waited on the clock (a manual clock just advances)
        for f in frames[::10]:
            assert measured_angle(tracker, f) == pytest.approx(rig.angle(f.t), abs=TOL)
        assert cam.stats()["dropped_frames"] == 0 and cam.flags() == ()


def test_mock_camera_frames_make_a_trace():
    clock = ManualClock()
    rig = SimRig(Pendulum(RIG, J_TRUE, {"viscous": {"c": VISCOUS_C}}), theta0=0.2, clock=clock, duration=10.0)
    rig.release()
    with open_camera(CONFIG, angle_source=rig.angle, clock=clock, imaging=IMAGING, seed=2) as cam:
        assert isinstance(cam, MockCamera)
        frames = [cam.grab() for _ in range(240)]
    trace = trace_from_tracking(track_frames(((f.t, f.image) for f in frames), CONFIG), CONFIG, source="mock")
    truth = np.array([rig.angle(t) for t in trace.t])
    assert np.max(np.abs(trace.angle - truth - np.mean(trace.angle - truth))) < TOL


def test_a_slow_reader_loses_frames_and_the_gaps_say_so():
    clock = ManualClock()
    cam = MockCamera(CONFIG, lambda t: 0.0, clock, seed=3)
    first = cam.grab()
    clock.advance(0.1)  # the reader was busy for 6 frame periods
    late = cam.grab()
    assert late.index == 6 and late.t == pytest.approx(0.1)
    assert cam.stats()["dropped_frames"] == 5 and cam.flags() == ("dropped_frames",)
    assert first.index == 0


def test_random_drops_are_counted_and_leave_index_gaps():
    clock = ManualClock()
    cam = MockCamera(CONFIG, lambda t: 0.05, clock, drop_probability=0.2, seed=4)
    frames = [cam.grab() for _ in range(100)]
    idx = np.array([f.index for f in frames])
    assert cam.stats()["dropped_frames"] == int(idx[-1] - idx[0] + 1 - idx.size) > 0
    assert np.allclose([f.t for f in frames], idx / 60.0)


def test_bare_callable_clock_and_close():
    cam = MockCamera(CONFIG, lambda t: 0.0, lambda: 5.0, seed=5)
    assert [cam.grab().t for _ in range(3)] == pytest.approx([5.0, 5.0 + 1 / 60, 5.0 + 2 / 60])
    cam.close()
    cam.close()
    with pytest.raises(SensorFault):
        cam.grab()
    with pytest.raises(DriverConfigError):
        MockCamera(CONFIG, lambda t: 0.0, lambda: 0.0, drop_probability=1.5)
    with pytest.raises(DriverConfigError, match="only to the mock"):
        open_camera(CONFIG, "/dev/null", imaging=IMAGING)


class FakeCapture:
    """cv2.VideoCapture's surface as V4L2Camera uses it: frames with kernel timestamps (ms)."""

    def __init__(self, stamps_ms, size=(640, 480), opened=True):
        self.stamps = list(stamps_ms)  # None: a failed read
        self.size = size
        self.opened = opened
        self.props = {}
        self.released = 0
        self.pos = 0.0
        self.args = None

    def __call__(self, *args):
        self.args = args
        return self

    def isOpened(self):
        return self.opened

    def set(self, prop, value):
        self.props[prop] = value
        return True

    def get(self, prop):
        if prop == cv2.CAP_PROP_FRAME_WIDTH:
            return self.size[0]
        if prop == cv2.CAP_PROP_FRAME_HEIGHT:
            return self.size[1]
        if prop == cv2.CAP_PROP_FPS:
            return self.props.get(cv2.CAP_PROP_FPS, 0.0)
        if prop == cv2.CAP_PROP_POS_MSEC:
            return self.pos
        return 0.0

    def read(self):
        stamp = self.stamps.pop(0) if self.stamps else None
        if stamp is None:
            return False, None
        self.pos = stamp
        return True, np.full((self.size[1], self.size[0], 3), 77, np.uint8)

    def release(self):
        self.released += 1


def test_v4l2_camera_settings_timestamps_and_drops():
    period = 1000 / 60
    stamps = [5000 + k * period for k in (0, 1, 2, 4, 5, 8)]  # frames 3, 6 and 7 never came
    fake = FakeCapture(stamps)
    cam = V4L2Camera(0, CAMERA, capture_factory=fake)
    assert fake.args == (0, cv2.CAP_V4L2)
    assert fake.props[cv2.CAP_PROP_FOURCC] == cv2.VideoWriter.fourcc(*"MJPG")
    assert fake.props[cv2.CAP_PROP_BUFFERSIZE] == 2 and fake.props[cv2.CAP_PROP_FPS] == 60.0
    frames = [cam.grab() for _ in range(6)]
    assert [f.index for f in frames] == [0, 1, 2, 4, 5, 8]
    assert frames[3].t == pytest.approx(5.0 + 4 / 60)
    assert frames[0].image.shape == (480, 640) and frames[0].image.dtype == np.uint8
    assert cam.stats()["dropped_frames"] == 3 and cam.flags() == ("dropped_frames",)
    cam.close()
    cam.close()
    assert fake.released == 1


def test_v4l2_camera_read_failures_then_fault():
    fake = FakeCapture([7000.0, None, None, 7000.0 + 2 * 1000 / 60] + [None] * 10)
    cam = V4L2Camera(0, CAMERA, capture_factory=fake, max_failures=5)
    cam.grab()
    assert cam.grab().index == 2  # two failed reads in between: recovered, and the gap shows the lost frame
    assert cam.stats()["read_failures"] == 2
    with pytest.raises(SensorFault, match="5 reads in a row failed"):
        cam.grab()


def test_v4l2_camera_without_buffer_timestamps_uses_the_host_clock():
    fake = FakeCapture([0.0, 0.0])
    times = iter([10.0, 10.02])
    cam = V4L2Camera(0, CAMERA, capture_factory=fake, clock=lambda: next(times))
    assert [cam.grab().t, cam.grab().t] == [10.0, 10.02]
    assert cam.stats()["host_timestamps"] == 2


def test_v4l2_camera_setup_errors():
    with pytest.raises(DriverConfigError, match="does not exist"):
        V4L2Camera("/dev/video-not-here", CAMERA, capture_factory=FakeCapture([]))
    closed = FakeCapture([], opened=False)
    with pytest.raises(DriverConfigError, match="cannot be opened"):
        V4L2Camera(0, CAMERA, capture_factory=closed)
    wrong = FakeCapture([], size=(1280, 720))
    with pytest.raises(DriverConfigError, match="1280×720"):
        V4L2Camera(0, CAMERA, capture_factory=wrong)
    assert wrong.released == 1
    with pytest.raises(DriverConfigError, match="buffer_size"):
        V4L2Camera(0, CAMERA, buffer_size=0, capture_factory=FakeCapture([]))


def test_both_cameras_are_cameras():
    assert issubclass(MockCamera, Camera) and issubclass(V4L2Camera, Camera)
