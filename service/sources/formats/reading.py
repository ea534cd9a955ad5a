"""A log as the traces of its releases: the columns chosen (``columns.py``), degrees and milliseconds
converted, a three-axis gyro reduced to its swing's axis (``measurement.axes``), a position to the angle
about the pivot, and the log split into its releases (``measurement.releases``)."""

from __future__ import annotations

import math

import numpy as np

from measurement.axes import SwingAxis, swing_axis
from measurement.releases import Release, Releases, find_releases
from measurement.trace import READING_UNITS, Trace
from service.errors import InputFileError

from .columns import ColumnChoice, Reading, choose, degrees, is_rate
from .log import Log

#: a named gyro axis carrying less of the swing than this cosine is the wrong axis
AXIS_COSINE = 0.95
#: the arc a circle fit needs to find the pivot of an x/y track, rad
MIN_ARC = 0.15


def _groups(log: Log) -> list[list[int]]:
    """The columns of each data set or run (one group when the file has one)."""
    names = list(dict.fromkeys(c.group for c in log.columns))
    return [[i for i, c in enumerate(log.columns) if c.group == g] for g in names]


def _time(log: Log, i: int) -> np.ndarray:
    t = log.column(i)
    return t / 1000.0 if log.columns[i].unit == "ms" else t


def _angle_about_pivot(x: np.ndarray, y: np.ndarray, pivot: tuple[float, float] | None) -> tuple[np.ndarray, dict]:
    """The angle of (x, y) about the pivot, zero along their mean direction (the hanging one); without a
    pivot, the centre of the circle the track lies on (least squares)."""
    facts: dict = {}
    if pivot is None:
        a = np.column_stack([x, y, np.ones_like(x)])
        (cx2, cy2, c), *_ = np.linalg.lstsq(a, x * x + y * y, rcond=None)
        pivot = (cx2 / 2, cy2 / 2)
        facts["pivot_fitted"] = True
    dx, dy = x - pivot[0], y - pivot[1]
    mx, my = float(np.mean(dx)), float(np.mean(dy))
    norm = math.hypot(mx, my)
    theta = np.arctan2(mx * dy - my * dx, mx * dx + my * dy) if norm > 0 else np.arctan2(dx, dy)
    facts.update({"pivot_x": float(pivot[0]), "pivot_y": float(pivot[1]),
                  "radius": float(np.median(np.hypot(dx, dy)))})
    return theta, facts


def _series(log: Log, r: Reading, choice: ColumnChoice) -> tuple[np.ndarray, np.ndarray, str, dict]:
    """t (s), the reading (rad or rad/s), its quantity and what was learnt choosing it."""
    t = _time(log, r.time)
    cols = [log.columns[i] for i in r.columns]
    facts: dict = {"time": log.columns[r.time].label, "reading": ", ".join(c.label for c in cols)}
    if r.kind == "xy":
        theta, more = _angle_about_pivot(log.column(r.columns[0]), log.column(r.columns[1]), choice.pivot)
        return t, theta, "angle", facts | more
    quantity = "angle" if r.kind == "angle" else "rate"
    y = np.column_stack([log.column(i) for i in r.columns])
    if any(degrees(log, i, choice.deg) for i in r.columns):
        y = np.radians(y)
        facts["converted"] = "degrees to rad"
    return t, (y if r.kind == "rates" else y[:, 0]), quantity, facts


def _finite(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    keep = np.isfinite(t) & (np.all(np.isfinite(y), axis=1) if y.ndim == 2 else np.isfinite(y))
    return t[keep], y[keep]


def _breaks(log: Log) -> tuple[tuple[float, str], ...]:
    return tuple((when, f"an event {what}") for what, when in log.events if what == "START")


def _axis(t: np.ndarray, rates: np.ndarray, breaks: tuple[tuple[float, str], ...]) -> tuple[SwingAxis, Releases]:
    """The swing's axis from the whole log, then again from its releases alone (handling between them
    turns the sensor about every axis)."""
    axis = swing_axis(rates)
    rel = find_releases(t, axis.rate, "rate", breaks)
    if rel.found:
        use = np.zeros(t.size, dtype=bool)
        for f in rel.found:
            use[f.i_start:f.i_stop] = True
        axis = swing_axis(rates, use)
        rel = find_releases(t, axis.rate, "rate", breaks)
    return axis, rel


def _axis_facts(log: Log, r: Reading, axis: SwingAxis) -> dict:
    names = [log.columns[i].label for i in r.columns]
    return {"axis": {"swing_about": names[axis.nearest], "cosine": axis.cosine, "share_of_variance": axis.share,
                     "direction": ", ".join(f"{c:+.3f}" for c in axis.direction),
                     "sensor_axes": ", ".join(names)}}


def _check_named_axis(log: Log, r: Reading, among: list[int], t: np.ndarray,
                      breaks: tuple[tuple[float, str], ...]) -> None:
    """A rate column named among a gyro's axes must carry the swing (advice naming the right axis)."""
    axes = [i for i in among if i != r.time and is_rate(log.columns[i]) and i not in r.columns
            and not log.columns[i].name.lower().startswith("abs")]
    if not r.named or r.kind != "rate" or len(axes) < 1:
        return
    cols = list(r.columns) + axes
    tt, rates = _finite(t, np.column_stack([log.column(i) for i in cols]))
    axis, _ = _axis(tt, rates, breaks)
    if axis.cosine_with(0) < AXIS_COSINE:
        best = log.columns[cols[axis.nearest]].label
        raise InputFileError(
            f"{log.source}: the swing is about {best!r} (cosine {axis.cosine:.3f} with it); --rate-col "
            f"{log.columns[r.columns[0]].label!r} reads {100 * axis.cosine_with(0):.0f} % of the swing's rate: the wrong "
            f"axis, not a scale to calibrate; give --rate-col {best!r}, or leave --rate-col out to take the swing's "
            "own direction from the three axes")


def log_traces(log: Log, choice: ColumnChoice | None = None) -> list[Trace]:
    """The traces of the releases in ``log``, in time order (InputFileError: none found)."""
    choice = choice or ColumnChoice()
    traces: list[Trace] = []
    skipped: list[str] = []
    for among in _groups(log):
        r = choose(log, among, choice)
        t, y, quantity, facts = _series(log, r, choice)
        t, y = _finite(t, y)
        breaks = _breaks(log)
        _check_named_axis(log, r, among, log.column(r.time), breaks)
        if r.kind == "rates":
            axis, rel = _axis(t, y, breaks)
            y = axis.rate
            facts |= _axis_facts(log, r, axis)
        else:
            rel = find_releases(t, y, quantity, breaks)
        skipped += [f"{s.start:.2f}–{s.stop:.2f} s: {s.why}" for s in rel.skipped]
        group = log.columns[among[0]].group
        for f in rel.found:
            traces.append(_release_trace(log, t, y, quantity, facts, f, group, len(traces) + 1))
    if not traces:
        raise InputFileError(f"{log.source}: no free swing found ({'; '.join(skipped) or 'no section'}); expected a "
                             "pendulum let go and swinging at least three full swings")
    if skipped:
        for tr in traces:
            tr.meta["log"]["sections_without_a_release"] = "; ".join(skipped)
    for tr in traces:
        tr.meta["release"]["of"] = len(traces)
    return traces


def _release_trace(log: Log, t: np.ndarray, y: np.ndarray, quantity: str, facts: dict, f: Release, group: str,
                   number: int) -> Trace:
    """The trace of release ``f``, its meta saying what was read, where the free swing starts and what was cut."""
    name = f"{log.source} #{number}" + (f" ({group})" if group else "")
    meta = {"log": {"format": log.format, "columns": {k: v for k, v in facts.items() if isinstance(v, str)}}
            | ({"notes": "; ".join(log.notes)} if log.notes else {}),
            "release": {"number": number, "free_swing_from": f.start, "until": f.stop, "cut_before": f.cut,
                        "section_begins": f.begins, "amplitude": f.amplitude, "unit": READING_UNITS[quantity]}}
    meta |= {k: v for k, v in facts.items() if isinstance(v, dict)}
    if "pivot_x" in facts:
        meta["position"] = {k: facts[k] for k in ("pivot_x", "pivot_y", "radius")} | {
            "pivot": "fitted (the track's circle)" if facts.get("pivot_fitted") else "given"}
    return Trace(t[f.i_start:f.i_stop], y[f.i_start:f.i_stop], source=name, meta=meta, quantity=quantity)
