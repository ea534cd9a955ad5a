"""The exports people bring, read as they come: each format recognised by its content, its columns and
units understood, a log split into its releases, a three-axis gyro read about the swing's axis; what
cannot be read is refused in one line that says why.

The files are built here from each tool's documented layout around a damped swing whose frequency is known.
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

W = 4.4  # rad/s
RATE = 100.0  # Hz


def swing(duration: float, amplitude: float = 0.4, hold: float = 0.0, zeta: float = 0.01, seed: int = 0):
    """(t, angle, rate) of a pendulum held at ``amplitude`` for ``hold`` s, then let go."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1 / RATE)
    s = np.clip(t - hold, 0.0, None)
    wd = W * math.sqrt(1 - zeta**2)
    env = amplitude * np.exp(-zeta * W * s)
    angle = env * (np.cos(wd * s) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * s))
    rate = np.gradient(angle, t)
    return t, angle + rng.normal(0, 2e-4, t.size), rate + rng.normal(0, 2e-3, t.size)


def phyphox_sections(n: int = 3, direction=(0.8, 0.6, 0.0)):
    """``n`` releases of a phone's three-axis gyro (hand-held 2 s before each), paused between them; the
    clock stops while paused. Returns the rows (t, x, y, z, |ω|), the (event, time) list and the release times."""
    rows, events, releases, clock = [], [], [], 0.0
    for k in range(n):
        t, _, rate = swing(14.0, hold=2.0, seed=k)
        rate = rate + np.where(t < 2.0, 0.05 * np.sin(9 * t), 0.0)  # the hand before the release
        vec = np.outer(rate, direction) + np.random.default_rng(10 + k).normal(0, 2e-3, (t.size, 3))
        events += [("START", clock), ("PAUSE", clock + t[-1])]
        releases.append(clock + 2.0)
        rows += [(clock + ti, *v, np.linalg.norm(v)) for ti, v in zip(t, vec)]
        clock += t[-1] + 0.01
    return rows, events, releases


def phyphox_log(folder: Path, n: int = 3, direction=(0.8, 0.6, 0.0)) -> list[float]:
    """phyphox's CSV export of ``phyphox_sections``. Returns the release times."""
    rows, events, releases = phyphox_sections(n, direction)
    (folder / "meta").mkdir(parents=True)
    (folder / "meta" / "time.csv").write_text(
        '"event","experiment time","system time","system time text"\n'
        + "".join(f'"{e}",{when:.15E},{1.7e9 + when:.15E},"x"\n' for e, when in events))
    (folder / "meta" / "device.csv").write_text('"property","value"\n"version","1.1.16"\n')
    (folder / "Raw Data.csv").write_text(
        '"Time (s)","Gyroscope x (rad/s)","Gyroscope y (rad/s)","Gyroscope z (rad/s)","Absolute (rad/s)"\n'
        + "".join(",".join(f"{v:.9E}" for v in r) + "\n" for r in rows))
    return releases


def test_a_phyphox_export_is_split_at_its_events_and_read_about_the_swings_axis(tmp_path):
    folder = tmp_path / "Gyroscope rotation rate 2025-03-07 14-02-08"
    releases = phyphox_log(folder)
    traces = load_releases(folder)
    assert len(traces) == 3
    for tr, t0 in zip(traces, releases):
        assert tr.quantity == "rate" and tr.meta["log"]["format"] == "phyphox"
        # the free swing starts at the release, the hand's 2 s before it cut
        assert abs(tr.meta["release"]["free_swing_from"] - t0) < 0.05
        axis = tr.meta["axis"]
        assert axis["swing_about"] == "Gyroscope x (rad/s)" and axis["cosine"] == pytest.approx(0.8, abs=0.01)
        # the projection on the swing's axis is the whole rate, not 0.8 of it
        assert np.max(np.abs(tr.angle)) == pytest.approx(0.4 * W, rel=0.03)


def test_a_zipped_phyphox_export_reads_as_its_folder(tmp_path):
    folder = tmp_path / "export"
    phyphox_log(folder, n=2)
    archive = tmp_path / "export.zip"
    with zipfile.ZipFile(archive, "w") as z:
        for f in folder.rglob("*"):
            if f.is_file():
                z.write(f, "export/" + f.relative_to(folder).as_posix())
    assert [tr.meta["release"]["free_swing_from"] for tr in load_releases(archive)] == \
        [tr.meta["release"]["free_swing_from"] for tr in load_releases(folder)]


def test_a_wrong_gyro_axis_is_named_not_taken_for_a_scale_to_calibrate(tmp_path):
    phyphox_log(tmp_path / "p", n=1, direction=(0.05, 0.999, 0.0))
    with pytest.raises(InputFileError) as e:
        load_releases(tmp_path / "p", columns=ColumnChoice(rate="Gyroscope x (rad/s)"))
    msg = str(e.value)
    assert "the swing is about 'Gyroscope y (rad/s)'" in msg and "the wrong axis, not a scale to calibrate" in msg
    assert load_releases(tmp_path / "p", columns=ColumnChoice(rate="Gyroscope y (rad/s)"))[0].quantity == "rate"


def test_a_phyphox_file_with_its_data_is_read_with_an_xml_parser(tmp_path):
    t, _, rate = swing(12.0)
    f = tmp_path / "pendulum.phyphox"
    f.write_text(
        '<phyphox xmlns="http://phyphox.org/xml" version="1.14"><title>Gyroscope</title><data-containers>'
        f'<container size="0" init="{",".join(f"{v:.6g}" for v in t)}">gyr_time</container>'
        f'<container size="0" init="{",".join(f"{v:.6g}" for v in rate)}">gyrX</container>'
        '</data-containers><export><set name="Gyroscope"><data name="Time (s)">gyr_time</data>'
        '<data name="Gyroscope x (rad/s)">gyrX</data></set></export></phyphox>')
    (tr,) = load_releases(f)
    assert tr.meta["log"]["format"] == "phyphox-xml" and tr.quantity == "rate" and len(tr) == t.size


def java_number(v: float) -> str:
    """A sample as phyphox's Android app writes it into a saved state (Java's DecimalFormat "0.#########E0")."""
    mantissa, exponent = f"{v:.9E}".split("E")
    return f"{mantissa.rstrip('0').rstrip('.')}E{int(exponent)}"


def phyphox_saved_state(path: Path, rows, events) -> None:
    """A .phyphox file as phyphox writes it on "save experiment state": the "Gyroscope (rotation rate)"
    experiment's own definition (data containers, sensor input, a view, the "Raw Data" export set) with each
    container's samples in its init attribute, then <state-title>, <color> and the <events> block."""
    cols = np.array(rows).T
    init = {name: ",".join(java_number(v) for v in col)
            for name, col in zip(("gyr_time", "gyrX", "gyrY", "gyrZ", "gyr"), cols)}
    containers = "".join(f'<container size="0" init="{init[b]}">{b}</container>' for b in ("gyrX", "gyrY", "gyrZ", "gyr",
                                                                                         "gyr_time"))
    outputs = "".join(f'<output component="{c}">{b}</output>' for c, b in
                      (("x", "gyrX"), ("y", "gyrY"), ("z", "gyrZ"), ("t", "gyr_time"), ("abs", "gyr")))
    data = "".join(f'<data name="{n}">{b}</data>' for n, b in
                   (("Time (s)", "gyr_time"), ("Gyroscope x (rad/s)", "gyrX"), ("Gyroscope y (rad/s)", "gyrY"),
                    ("Gyroscope z (rad/s)", "gyrZ"), ("Absolute (rad/s)", "gyr")))
    system_ms = 1741384636161
    marks = "".join(f'<{e.lower()} experimentTime="{float(when)!r}" systemTime="{system_ms + int(1000 * when) + 5000 * k}"/>'
                    for k, (e, when) in enumerate(events))
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8" standalone="no"?><phyphox locale="en" version="1.14">\n'
        "  <title>Gyroscope (rotation rate)</title>\n  <category>Raw Sensors</category>\n"
        f"  <data-containers>{containers}</data-containers>\n"
        f'  <input><sensor type="gyroscope">{outputs}</sensor></input>\n'
        '  <views><view label="Graph"><graph label="Gyroscope x" timeOnX="true"><input axis="x">gyr_time</input>'
        '<input axis="y">gyrX</input></graph></view></views>\n'
        f'  <export><set name="Raw Data">{data}</set></export>\n'
        "<state-title>racquet</state-title><color>blue</color>"
        f"<events>{marks}</events></phyphox>", encoding="utf-8")


def test_a_saved_phyphox_state_is_split_at_its_start_and_pause_events(tmp_path):
    rows, events, releases = phyphox_sections(3)
    f = tmp_path / "Gyroscope rotation rate.phyphox"
    phyphox_saved_state(f, rows, events)
    log = read_log(f)
    assert log.format == "phyphox-xml" and log.events == tuple(events)
    assert [c.label for c in log.columns][:2] == ["Time (s)", "Gyroscope x (rad/s)"]
    assert log.data.shape == (len(rows), 5)
    traces = load_releases(f)
    assert len(traces) == 3
    for tr, t0 in zip(traces, releases):
        assert abs(tr.meta["release"]["free_swing_from"] - t0) < 0.05
        assert tr.meta["axis"]["swing_about"] == "Gyroscope x (rad/s)"
    # the same log exported as CSV reads to the same releases
    phyphox_log(tmp_path / "csv", n=3)
    assert [tr.meta["release"]["free_swing_from"] for tr in load_releases(tmp_path / "csv")] == \
        pytest.approx([tr.meta["release"]["free_swing_from"] for tr in traces], abs=1e-6)


def test_a_phyphox_event_without_its_time_is_refused_in_one_line(tmp_path):
    rows, events, _ = phyphox_sections(1)
    f = tmp_path / "p.phyphox"
    phyphox_saved_state(f, rows, events)
    f.write_text(f.read_text().replace('<pause experimentTime="', '<pause experimentTim="'))
    with pytest.raises(InputFileError, match="a <pause> event with experimentTime None; expected the experiment"):
        read_log(f)


def test_a_tracker_export_with_a_mass_line_crlf_and_tabs_gives_the_angle_about_the_pivot(tmp_path):
    t, angle, _ = swing(20.0, amplitude=0.3)
    length = 1.2
    lines = ["mass_B", "t\tx\ty\tfunc"] + [f"{ti}\t{length * math.sin(a)}\t{-length * math.cos(a)}\t{a}"
                                          for ti, a in zip(t, angle)]
    f = tmp_path / "8049.txt"
    f.write_bytes("\r\n".join(lines).encode() + b"\r\n")
    assert read_log(f).format == "tracker"
    (tr,) = load_releases(f)
    assert tr.quantity == "angle" and np.max(np.abs(tr.angle - angle)) < 2e-3
    assert tr.meta["position"]["radius"] == pytest.approx(length, rel=1e-3)
    assert "mass_B" in tr.meta["log"]["notes"]


def test_a_logger_pro_export_in_degrees_gives_each_run_as_a_release(tmp_path):
    t1, a1, _ = swing(15.0, seed=1)
    t2, a2, _ = swing(12.0, amplitude=0.3, seed=2)
    rows = ['"Run 1: Time (s)","Run 1: Angle (°)","Run 2: Time (s)","Run 2: Angle (°)"']
    for i in range(t1.size):
        right = f"{t2[i]},{math.degrees(a2[i])}" if i < t2.size else ","
        rows.append(f"{t1[i]},{math.degrees(a1[i])},{right}")
    f = tmp_path / "pendulum.csv"
    f.write_text("\n".join(rows) + "\n")
    one, two = load_releases(f)
    assert one.meta["log"]["format"] == "logger-pro" and len(two) == t2.size
    assert np.max(np.abs(one.angle)) == pytest.approx(0.4, rel=0.02)  # degrees read as degrees


def test_a_capstone_export_is_recognised_by_its_run_columns(tmp_path):
    t, angle, _ = swing(12.0)
    f = tmp_path / "capstone.csv"
    f.write_text("Time (s) Run #1,Angle (rad) Run #1\n" + "".join(f"{a},{b}\n" for a, b in zip(t, angle)))
    (tr,) = load_releases(f)
    assert tr.meta["log"]["format"] == "capstone" and tr.quantity == "angle"


def test_a_semicolon_table_with_a_decimal_comma_and_no_header_is_reported_as_such(tmp_path):
    t, _, rate = swing(12.0)
    f = tmp_path / "microbit.csv"
    f.write_text("".join(f"{a:.4f};{math.degrees(b):.4f}\n".replace(".", ",") for a, b in zip(t, rate)))
    with pytest.raises(InputFileError, match="has no header.*first row is data.*--time-col 1"):
        load_releases(f)
    (tr,) = load_releases(f, columns=ColumnChoice(time="1", rate="2", deg=True))
    assert tr.quantity == "rate" and np.max(np.abs(tr.angle)) == pytest.approx(0.4 * W, rel=0.03)
    assert "decimal comma" in tr.meta["log"]["notes"]


def test_a_tab_separated_table_is_split_into_its_columns(tmp_path):
    t, angle, _ = swing(12.0)
    f = tmp_path / "log.tsv"
    f.write_text("time\ttheta\n" + "".join(f"{a}\t{b}\n" for a, b in zip(t, angle)))
    (tr,) = load_releases(f)
    assert tr.meta["log"]["columns"] == {"time": "time", "reading": "theta"}


def test_an_accelerometer_alone_is_refused_naming_why_its_tilt_is_not_the_angle(tmp_path):
    t, angle, _ = swing(12.0)
    f = tmp_path / "acc.csv"
    f.write_text("Time (s),Acceleration x (m/s^2),Acceleration y (m/s^2)\n"
                 + "".join(f"{a},{9.8 * math.sin(b)},{9.8 * math.cos(b)}\n" for a, b in zip(t, angle)))
    with pytest.raises(InputFileError, match="accelerometer.*tilt is not the swing angle"):
        load_releases(f)
    with pytest.raises(InputFileError, match="named as the angle.*tilt is not the swing angle"):
        load_releases(f, columns=ColumnChoice(angle="2"))


def test_xy_pixels_about_a_given_pivot(tmp_path):
    t, angle, _ = swing(12.0)
    f = tmp_path / "track.csv"
    f.write_text("frame_time,bx,by\n" + "".join(f"{a},{320 + 200 * math.sin(b)},{40 + 200 * math.cos(b)}\n"
                                                 for a, b in zip(t, angle)))
    (tr,) = load_releases(f, columns=ColumnChoice(time="frame_time", xy="bx,by", pivot=(320.0, 40.0)))
    # the angle about the pivot, its zero along the mean direction (the fit takes the offset), either sign
    assert min(np.std(tr.angle - angle), np.std(tr.angle + angle)) < 1e-5 and tr.meta["position"]["pivot"] == "given"


def test_moi_s_own_trace_csv_is_read_as_before_and_searched_for_releases_when_its_columns_are_named(tmp_path):
    t, _, rate = swing(14.0, hold=3.0)
    f = tmp_path / "swing.csv"
    f.write_text("t,rate\n" + "".join(f"{a},{b}\n" for a, b in zip(t, rate)))
    (tr,) = load_releases(f)
    assert tr.meta == {} and len(tr) == t.size
    (tr,) = load_releases(f, columns=ColumnChoice(rate="rate"))
    assert tr.meta["release"]["free_swing_from"] == pytest.approx(3.0, abs=0.05)


def test_moi_s_own_trace_csv_holding_two_releases_gives_each_of_them(tmp_path):
    """Two swings saved in one file of moi's own columns (the pendulum at rest for 4 s between them, the
    second held 2 s, then let go) are two releases, never one fit across both; a gap in the clock alone is a
    sensor's dropout within one swing, which the identification's window handles."""
    t1, a1, _ = swing(12.0, amplitude=0.4, seed=1)
    rest = np.random.default_rng(3).normal(0, 2e-4, 400)
    t2, a2, _ = swing(14.0, amplitude=0.3, hold=2.0, seed=2)
    t = np.arange(t1.size + rest.size + t2.size) / RATE
    f = tmp_path / "two.csv"
    f.write_text("t,angle\n" + "".join(f"{a},{b}\n" for a, b in zip(t, np.concatenate([a1, rest, a2]))))
    first, second = load_releases(f)
    assert first.t[0] == pytest.approx(0.0, abs=0.05) and first.t[-1] < 18.0  # to the hold before the second
    # the free swing starts at a turning point after the hold (the held plateau itself, or the first one
    # after it: an angle record's hold has no excursion before it to tell a turning point by)
    let_go, period = 18.0, 2 * math.pi / W
    assert let_go - 0.05 <= second.meta["release"]["free_swing_from"] <= let_go + 0.5 * period + 0.05
    assert second.meta["release"]["amplitude"] == pytest.approx(0.3, abs=0.01)
    gapped = tmp_path / "gap.csv"
    t_gap = np.concatenate([t1[:600], t1[600:] + 3.0])
    gapped.write_text("t,angle\n" + "".join(f"{a},{b}\n" for a, b in zip(t_gap, a1)))
    (whole,) = load_releases(gapped)
    assert len(whole) == t1.size and whole.meta == {}


def test_a_spreadsheet_is_refused_in_one_line_asking_for_csv(tmp_path):
    f = tmp_path / "log.xlsx"
    with zipfile.ZipFile(f, "w") as z:
        z.writestr("xl/workbook.xml", "<workbook/>")
    with pytest.raises(InputFileError, match="save it as CSV"):
        load_releases(f)


def test_three_unlabelled_axes_are_not_taken_for_a_position(tmp_path):
    t, angle, _ = swing(12.0)
    f = tmp_path / "microbit.csv"
    f.write_text("Time (seconds),x,y,z\n" + "".join(f"{a},{-1000 * math.sin(b)},{-1000 * math.cos(b)},12\n"
                                                     for a, b in zip(t, angle)))
    with pytest.raises(InputFileError, match="three-axis sensor.*--rate-col.*--xy"):
        load_releases(f)
