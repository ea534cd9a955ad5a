"""A Tracker project (.trk) read for its marked tracks: marks in image pixels turned into the file's own
coordinate system frame by frame, times from the clip, the angle about the pivot; a project without marks,
or with several marked tracks and none named, refused in one line.

The projects are built here in the XML Tracker saves (a TrackerPanel holding its video clip, clip control,
coordinate system, length unit and tracks, each point mass's marks indexed by frame number, the coordinate
system saved at frame 0 and at its key frames) around a damped swing whose angle is known at every frame.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np
import pytest

from service.errors import InputFileError
from service.sources.dispatch import load_releases
from service.sources.formats.columns import ColumnChoice
from service.sources.formats.registry import read_log

TRACKER = "org.opensourcephysics.cabrillo.tracker."
MEDIA = "org.opensourcephysics.media.core."
PIVOT = (0.12, 0.55)  # m, in the world
LENGTH = 0.9  # m
W = 4.4  # rad/s
START, STEP, COUNT, T0, DT = 12, 2, 900, 0.5, 1000 / 60  # clip: frames 12, 14, ...; 0.5 s; 60 frames/s
#: the coordinate system: (from frame, origin x, origin y px, angle deg, px per m); the camera nudged at 900
SYSTEMS = ((0, 310.0, 95.0, 0.0, 420.0), (900, 352.5, 71.0, 3.5, 418.0))


def prop(name: str, kind: str, value: str) -> str:
    return f'<property name="{name}" type="{kind}">{value}</property>'


def obj(cls: str, *props: str) -> str:
    return f'<object class="{cls}">{"".join(props)}</object>'


def array(name: str, cls: str, items: dict[int, str]) -> str:
    return (f'<property name="{name}" type="array" class="[L{cls};">'
            + "".join(f'<property name="[{n}]" type="object">{o}</property>' for n, o in sorted(items.items()))
            + "</property>")


def angle_at(frame: int) -> float:
    t = T0 + (frame - START) * DT / 1000
    return 0.3 * math.exp(-0.01 * W * t) * math.cos(W * t)


def system(frame: int) -> tuple[float, ...]:
    return [s for s in SYSTEMS if s[0] <= frame][-1][1:]


def to_image(xw: float, yw: float, frame: int) -> tuple[float, float]:
    tx, ty, deg, scale = system(frame)
    a = math.radians(deg)
    return scale * (math.cos(a) * xw - math.sin(a) * yw) + tx, -scale * (math.sin(a) * xw + math.cos(a) * yw) + ty


def mark(frame: int, angle: float | None = None) -> str:
    a = angle_at(frame) if angle is None else angle
    x, y = to_image(PIVOT[0] + LENGTH * math.sin(a), PIVOT[1] - LENGTH * math.cos(a), frame)
    return obj(TRACKER + "PointMass$FrameData", prop("x", "double", repr(x)), prop("y", "double", repr(y)))


def point_mass(name: str, marks: dict[int, str]) -> str:
    return obj(TRACKER + "PointMass", prop("mass", "double", "1.0"), prop("name", "string", name),
               prop("footprint", "string", "Footprint.Diamond"),
               array("framedata", TRACKER + "PointMass$FrameData", marks))


def project(path: Path, *tracks: str) -> Path:
    steps = [START + STEP * k for k in range(COUNT)]
    coords = {s[0]: obj(MEDIA + "ImageCoordSystem$FrameData", prop("xorigin", "double", str(s[1])),
                        prop("yorigin", "double", str(s[2])), prop("angle", "double", str(s[3])),
                        prop("xscale", "double", str(s[4])), prop("yscale", "double", str(s[4]))) for s in SYSTEMS}
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n' + obj(
            TRACKER + "TrackerPanel", prop("semantic_version", "string", "6.1.6"),
            '<property name="videoclip" type="object">' + obj(
                MEDIA + "VideoClip",
                '<property name="video" type="object">' + obj(
                    "org.opensourcephysics.media.xuggle.XuggleVideo", prop("path", "string", "pendulum.mp4")) + "</property>",
                prop("video_framecount", "int", str(steps[-1] + 30)), prop("startframe", "int", str(START)),
                prop("stepsize", "int", str(STEP)), prop("stepcount", "int", str(COUNT)),
                prop("starttime", "double", str(1000 * T0)), prop("readout", "string", "time")) + "</property>",
            '<property name="clipcontrol" type="object">' + obj(
                MEDIA + "VideoClipControl", prop("rate", "double", "1.0"), prop("delta_t", "double", repr(DT)),
                prop("frame", "int", str(START))) + "</property>",
            '<property name="coords" type="object">' + obj(
                MEDIA + "ImageCoordSystem", prop("fixedorigin", "boolean", "false"),
                prop("fixedangle", "boolean", "false"), prop("fixedscale", "boolean", "false"),
                prop("locked", "boolean", "false"),
                array("framedata", MEDIA + "ImageCoordSystem$FrameData", coords)) + "</property>",
            prop("length_unit", "string", "m"), prop("mass_unit", "string", "kg"),
            '<property name="tracks" type="collection" class="java.util.ArrayList">'
            + "".join(f'<property name="item" type="object">{t}</property>' for t in tracks) + "</property>"),
        encoding="utf-8")
    return path


def bob(name: str = "bob") -> str:
    marks = {START + STEP * k: mark(START + STEP * k) for k in range(COUNT)}
    marks[START + 1] = mark(START + 1, angle=1.2)  # a mark between two steps: not in Tracker's table
    return point_mass(name, marks)


AXES = obj(TRACKER + "CoordAxes", prop("name", "string", "axes"))
MODEL = obj(TRACKER + "DynamicParticle", prop("mass", "double", "1.0"), prop("name", "string", "model A"))


def test_a_tracker_project_s_marks_are_turned_into_its_coordinate_system_frame_by_frame(tmp_path):
    f = project(tmp_path / "pendulum.trk", AXES, bob(), MODEL)
    log = read_log(f)
    assert log.format == "tracker-trk"
    assert [c.label for c in log.columns] == ["t (s)", "x_{bob} (m)", "y_{bob} (m)"]
    frames = np.arange(COUNT) * STEP + START
    assert log.column(0) == pytest.approx(T0 + (frames - START) * DT / 1000, abs=1e-12)
    angles = np.array([angle_at(int(n)) for n in frames])
    x, y = PIVOT[0] + LENGTH * np.sin(angles), PIVOT[1] - LENGTH * np.cos(angles)
    assert np.max(np.abs(log.column(1) - x)) < 1e-9 and np.max(np.abs(log.column(2) - y)) < 1e-9
    assert "1 mark(s) of 'bob' on frames that are not steps of the clip left out" in log.notes
    assert "'model A' (DynamicParticle)" in log.notes[0]


def test_a_tracker_project_gives_the_angle_about_the_pivot_at_the_clip_s_times(tmp_path):
    (tr,) = load_releases(project(tmp_path / "pendulum.trk", AXES, bob()))
    assert tr.quantity == "angle" and tr.meta["log"]["format"] == "tracker-trk"
    frames = np.round((tr.t - T0) * 1000 / DT).astype(int) + START
    assert np.all((frames - START) % STEP == 0)
    error = tr.angle - [angle_at(n) for n in frames]
    # zero along the track's mean direction (the hanging one, to within the swing's asymmetry)
    assert np.ptp(error) < 1e-6 and abs(np.mean(error)) < 2e-3
    assert tr.meta["position"]["radius"] == pytest.approx(LENGTH, rel=1e-6)
    assert (tr.meta["position"]["pivot_x"], tr.meta["position"]["pivot_y"]) == pytest.approx(PIVOT, abs=1e-6)


def test_several_marked_tracks_are_named_and_one_is_chosen_by_its_name(tmp_path):
    still = point_mass("pivot mark", {START + STEP * k: mark(START + STEP * k, angle=0.0) for k in range(0, COUNT, 5)})
    f = project(tmp_path / "two.trk", bob(), still)
    with pytest.raises(InputFileError, match=r"several positions \('x_\{bob\} \(m\)', 'x_\{pivot mark\} \(m\)'.*--xy NAME"):
        load_releases(f)
    (tr,) = load_releases(f, columns=ColumnChoice(xy="bob"))
    assert tr.meta["log"]["columns"]["reading"] == "x_{bob} (m), y_{bob} (m)"
    (tr2,) = load_releases(f, columns=ColumnChoice(xy="x_{bob} (m),y_{bob} (m)"))
    assert np.array_equal(tr.angle, tr2.angle)


def test_a_tracker_project_without_marks_inside_is_refused_in_one_line(tmp_path):
    f = project(tmp_path / "model.trk", AXES, MODEL)
    with pytest.raises(InputFileError) as e:
        load_releases(f)
    msg = str(e.value)
    assert "without marked positions inside (tracks: 'axes' (CoordAxes), 'model A' (DynamicParticle))" in msg
    assert "File > Export > Data" in msg and "\n" not in msg


def test_a_tracker_tab_set_is_refused_asking_for_the_tab_s_own_project(tmp_path):
    f = tmp_path / "tabs.trk"
    f.write_text('<?xml version="1.0" encoding="UTF-8"?>\n' + obj(
        TRACKER + "TFrame", '<property name="tabs" type="array" class="[[Ljava.lang.String;">'
        '<property name="[0]" type="array" class="[Ljava.lang.String;"><property name="[0]" type="string">'
        "/home/a/pendulum.trk</property></property></property>"))
    with pytest.raises(InputFileError, match="a Tracker tab set .* expected the .trk of the tab that holds the swing"):
        read_log(f)


def test_a_tracker_project_zip_reads_as_the_project_inside_it(tmp_path):
    f = project(tmp_path / "pendulum.trk", AXES, bob())
    trz = tmp_path / "pendulum.trz"
    with zipfile.ZipFile(trz, "w") as z:
        z.write(f, "pendulum/pendulum.trk")
        z.writestr("pendulum/pendulum.mp4", b"\x00\x00\x00\x18ftypmp42")
        z.writestr("pendulum/pendulum_info.html", "<html></html>")
    log = read_log(trz)
    assert log.format == "tracker-trk" and np.array_equal(log.data, read_log(f).data)
