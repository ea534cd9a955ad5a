"""`moi markers`: a trace CSV from two tracked markers, the camera's view measured and removed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from measurement import parse_trace_csv
from service.cli import main

DATA = Path(__file__).resolve().parents[2] / "data"


def _trace(text: str, source: str):
    return parse_trace_csv(text.splitlines(), source=source)


def test_as_seen_it_is_the_tracked_angle_of_the_same_release(capsys):
    assert main(["markers", str(DATA / "wood_markers_60deg.csv"), "--as-seen"]) == 0
    out = capsys.readouterr().out
    mine = _trace(out, "markers")
    with open(DATA / "wood_pendulum_60deg.csv", encoding="utf-8") as fh:
        tracked = parse_trace_csv(fh, source="tracked")
    assert np.array_equal(mine.t, tracked.t)
    assert np.max(np.abs(mine.angle - tracked.angle)) < 1e-6  # the tracked file kept 6 decimals
    assert "view not measured" in out


def test_the_view_is_measured_reported_and_written_with_the_trace(tmp_path, capsys):
    out_file = tmp_path / "w120.csv"
    assert main(["markers", str(DATA / "wood_markers_120deg.csv"), "--out", str(out_file)]) == 0
    said = capsys.readouterr().out
    assert "axis ratio" in said and f"trace written to {out_file}" in said
    text = out_file.read_text(encoding="utf-8")
    comments = [line for line in text.splitlines() if line.startswith("#")]
    assert any("camera view measured from the marker pair" in line for line in comments)
    assert any("[sensor] calibrated = true" in line for line in comments)
    trace = _trace(text, "w120")
    with open(DATA / "wood_pendulum_120deg.csv", encoding="utf-8") as fh:
        tracked = parse_trace_csv(fh, source="tracked")
    assert len(trace) == len(tracked)
    # corrected by a few hundredths of a rad at the largest swing, not more
    change = (trace.angle - trace.angle.mean()) - (tracked.angle - tracked.angle.mean())
    assert 0.005 < np.max(np.abs(change)) < 0.1


@pytest.mark.parametrize(("body", "expected"), [
    ("t,ax,ay,bx\n0,1,2,3\n", "missing column(s) by"),
    ("t,ax,ay,bx,by\n0,1,2,3,x\n", "non-numeric"),
    ("t,ax,ay,bx,by\n" + "".join(f"{i / 60},0,0,0,{100 + i}\n" for i in range(100)), "turns by only"),
])
def test_bad_marker_files_are_one_line(tmp_path, capsys, body, expected):
    f = tmp_path / "m.csv"
    f.write_text(body, encoding="utf-8")
    assert main(["markers", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0]


def test_a_missing_marker_file_is_one_line(tmp_path, capsys):
    assert main(["markers", str(tmp_path / "none.csv")]) == 2
    assert "not found" in capsys.readouterr().err
