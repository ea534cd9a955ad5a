"""A Tracker project (``.trk``, or the zip ``.trz`` holding it): the XML Tracker saves, read for its
point-mass tracks' positions.

Tracker keeps a point mass's marks in image pixels, one per video frame (``framedata``, indexed by frame
number), and the coordinate system beside them (``coords``: per frame the image position of the world
origin, the x axis's angle in degrees counter-clockwise and the scale in pixels per world unit; a frame
without its own entry keeps the last one before it). A step's world position is the mark turned into that
frame's system (world y up). Its time is the clip's: ``starttime`` (ms) plus the frames since the clip's
``startframe`` times the mean frame duration (``clipcontrol``'s ``delta_t``, ms), as Tracker gives a video
of constant frame rate; marks on frames that are not steps of the clip (``startframe``, ``stepsize``,
``stepcount``) are not in Tracker's own data table and are left out here too.

Every track with marks becomes the columns ``x_{NAME}``, ``y_{NAME}``; with several, ``--xy`` names one.
A model or a centre of mass has no marks inside the file: a project with no marked track is refused.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from service.errors import InputFileError

from .log import Column, Log
from .registry import Format, Probe, member_text, whole_text

PANEL = "org.opensourcephysics.cabrillo.tracker.TrackerPanel"
MARK = "org.opensourcephysics.cabrillo.tracker.PointMass$FrameData"


def _zipped(probe: Probe) -> list[str]:
    """The projects inside a Tracker project zip (``.trz``: the .trk with its video and notes)."""
    return [m for m in probe.members if m.lower().endswith(".trk")]


def sniff(probe: Probe) -> bool:
    if probe.path.is_file() and _zipped(probe):
        return True
    return probe.head.lstrip().startswith("<?xml") and "org.opensourcephysics.cabrillo.tracker" in probe.head


def _prop(obj: ET.Element, name: str) -> ET.Element | None:
    return next((p for p in obj if p.tag == "property" and p.get("name") == name), None)


def _number(obj: ET.Element, name: str, default: float | None = None) -> float:
    p = _prop(obj, name)
    if p is None or not (p.text or "").strip():
        if default is None:
            raise InputFileError(f"a Tracker {obj.get('class', 'object').rsplit('.', 1)[-1]} without its {name!r}")
        return default
    try:
        return float(p.text or "")
    except ValueError:
        raise InputFileError(f"a Tracker property {name!r} of {p.text!r}: expected a number") from None


def _object(obj: ET.Element, name: str) -> ET.Element | None:
    p = _prop(obj, name)
    return None if p is None else p.find("object")


def _items(array: ET.Element | None) -> dict[int, ET.Element]:
    """The objects of an array property by index (``[n]``; an index left out is a null)."""
    out = {}
    for p in array if array is not None else ():
        name, obj = p.get("name") or "", p.find("object")
        if obj is not None and name.startswith("[") and name.endswith("]") and name[1:-1].isdigit():
            out[int(name[1:-1])] = obj
    return out


@dataclass(frozen=True)
class Clip:
    """The video clip's steps: frame of step 0, frames per step, steps, time of step 0 (s), frame duration (s)."""

    start: int
    step: int
    count: int
    t0: float
    dt: float

    def steps(self) -> range:
        return range(self.start, self.start + self.step * self.count, self.step)

    def time(self, frame: int) -> float:
        return self.t0 + (frame - self.start) * self.dt


def _clip(panel: ET.Element) -> Clip:
    clip, control = _object(panel, "videoclip"), _object(panel, "clipcontrol")
    if clip is None or control is None:
        raise InputFileError("a Tracker project without its video clip and clip control (the frame times)")
    start = int(_number(clip, "startframe", 0.0)) - int(_number(clip, "frameshift", 0.0))
    dt = _number(control, "delta_t")
    if not (math.isfinite(dt) and dt > 0):
        raise InputFileError(f"a Tracker clip with a frame duration of {dt} ms; expected a positive time")
    t0 = _number(clip, "starttime", 0.0)  # NaN: Tracker's default, 0
    return Clip(start, max(1, int(_number(clip, "stepsize", 1.0))), int(_number(clip, "stepcount")),
                t0 / 1000.0 if math.isfinite(t0) else 0.0, dt / 1000.0)


def _coords(panel: ET.Element, frames: int) -> np.ndarray:
    """Per frame (rows 0..frames-1): origin x, origin y (px), angle (rad), x scale, y scale (px per unit)."""
    coords = _object(panel, "coords")
    keys = _items(_prop(coords, "framedata") if coords is not None else None)
    if 0 not in keys:
        raise InputFileError("a Tracker project without its coordinate system's first frame (coords framedata [0])")
    out = np.empty((frames, 5))
    for n in range(frames):
        if n in keys:
            k = keys[n]
            row = [_number(k, "xorigin"), _number(k, "yorigin"), math.radians(_number(k, "angle")),
                   _number(k, "xscale"), _number(k, "yscale")]
        out[n] = row
    return out


def to_world(x: np.ndarray, y: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image pixels (y down) to world units (y up) in the systems ``c`` (rows as ``_coords``)."""
    u = (x - c[:, 0]) / c[:, 3]
    v = -(y - c[:, 1]) / c[:, 4]
    cos, sin = np.cos(c[:, 2]), np.sin(c[:, 2])
    return cos * u + sin * v, -sin * u + cos * v


def _tracks(panel: ET.Element) -> tuple[list[tuple[str, dict[int, tuple[float, float]]]], list[str]]:
    """(name, marks by frame) of each track with point-mass marks, and 'name (kind)' of the others."""
    marked, other = [], []
    tracks = _prop(panel, "tracks")
    for item in tracks if tracks is not None else ():
        obj = item.find("object")
        if obj is None:
            continue
        name_el = _prop(obj, "name")
        name = (name_el.text or "").strip() if name_el is not None else "?"
        frames = {n: o for n, o in _items(_prop(obj, "framedata")).items() if o.get("class") == MARK}
        if frames:
            marked.append((name, {n: (_number(o, "x"), _number(o, "y")) for n, o in frames.items()}))
        else:
            other.append(f"{name!r} ({(obj.get('class') or '?').rsplit('.', 1)[-1]})")
    return marked, other


def _panel(root: ET.Element, source: str) -> ET.Element:
    panels = [root] if root.get("class") == PANEL else [o for o in root.iter("object") if o.get("class") == PANEL]
    if not panels:
        raise InputFileError(f"{source}: a Tracker tab set (it names the tabs' own files, {root.get('class')!r}); "
                             "expected the .trk of the tab that holds the swing")
    if len(panels) > 1:
        raise InputFileError(f"{source}: a Tracker file with {len(panels)} tabs; expected one (save the tab that "
                             "holds the swing as its own .trk)")
    return panels[0]


def read(probe: Probe) -> Log:
    source = str(probe.path)
    inside = _zipped(probe)
    if len(inside) > 1:
        raise InputFileError(f"{source}: a Tracker zip holding {len(inside)} projects ({', '.join(inside)}); expected "
                             "one (export the zip from the tab that holds the swing)")
    try:
        text = member_text(probe, inside[0], "Tracker project") if inside else whole_text(probe, "Tracker project")
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputFileError(f"{source!r} is not valid XML: {exc}") from None
    try:
        return _log(_panel(root, source), source)
    except InputFileError as exc:
        msg = str(exc)
        raise InputFileError(msg if msg.startswith(source) else f"{source}: {msg}") from None


def _log(panel: ET.Element, source: str) -> Log:
    marked, other = _tracks(panel)
    if not marked:
        raise InputFileError(
            f"{source}: a Tracker project without marked positions inside (tracks: {', '.join(other) or 'none'}); "
            "expected a point-mass track marked on the video, or its data table (File > Export > Data)")
    clip = _clip(panel)
    steps = clip.steps()
    frames = sorted({n for _, marks in marked for n in marks if n in steps})
    if not frames:
        raise InputFileError(f"{source}: the tracks' marks lie outside the video clip's steps (frames "
                             f"{steps.start}–{steps.stop - 1} every {clip.step}); expected marks on the clip's steps")
    c = _coords(panel, frames[-1] + 1)[frames]
    unit_el = _prop(panel, "length_unit")
    unit = (unit_el.text or "").strip() if unit_el is not None else ""
    labels, cols = ["t (s)"], [np.array([clip.time(n) for n in frames])]
    left_out = []
    for name, marks in marked:
        xy = np.array([marks.get(n, (np.nan, np.nan)) for n in frames])
        xw, yw = to_world(xy[:, 0], xy[:, 1], c)
        # a label's colon, brackets and parentheses would read as a data set's name or a unit
        clean = re.sub(r"[:()\[\]]", " ", name).strip()
        labels += [f"{a}_{{{clean}}}" + (f" ({unit})" if unit else "") for a in "xy"]
        cols += [xw, yw]
        if outside := sum(1 for n in marks if n not in steps):
            left_out.append(f"{outside} mark(s) of {name!r} on frames that are not steps of the clip left out")
    notes = (f"Tracker project: {len(frames)} steps, frames {frames[0]}–{frames[-1]} every {clip.step}, "
             f"frame duration {1000 * clip.dt:.6g} ms; positions in {unit or 'world units'} through the file's "
             f"coordinate system; tracks without marks: {', '.join(other) or 'none'}", *left_out)
    return Log(source, "tracker-trk", tuple(Column.parse(lb) for lb in labels), np.column_stack(cols), notes=notes)


FORMAT = Format(
    "tracker-trk", "a Tracker project (.trk, or its zip .trz) with marked point-mass tracks: positions turned into the file's "
                   "coordinate system (origin, angle, scale per frame), times from its clip (start time, frame "
                   "duration); the angle from the pivot; several marked tracks: --xy NAME",
    "moi identify pendulum.trk --rig string.toml", sniff, read)
