"""Which columns of a log hold the time and the swing: named by the user (--time-col, --angle-col,
--rate-col, --xy: a label or a number from 1), else recognised by their names and units."""

from __future__ import annotations

import re
from dataclasses import dataclass

from service.errors import InputFileError

from .log import Column, Log

ANGLE_UNITS = {"rad": 1.0, "°": None, "deg": None, "degree": None, "degrees": None}
RATE_UNITS = {"rad/s": 1.0, "°/s": None, "deg/s": None, "degrees/s": None, "1/s": 1.0}
ACCELERATION_UNITS = {"m/s²", "m/s^2", "m/s2", "g"}
_TIME = re.compile(r"^(t|time|zeit|temps|tiempo)(_.*)?$", re.IGNORECASE)
_ANGLE = re.compile(r"angle|theta|θ|winkel|phi\b", re.IGNORECASE)
_RATE = re.compile(r"gyro|rate|angular velocity|ω|omega|^w[xyz]?\b", re.IGNORECASE)
_NORM = re.compile(r"absolute|\babs\b|magnitude|norm|total|resultant", re.IGNORECASE)
_ACCEL = re.compile(r"acc", re.IGNORECASE)
_POSITION = re.compile(r"^(position\s*)?([xyz])(\b|_|$)", re.IGNORECASE)
_NOT_POSITION = re.compile(r"veloc|speed|acc|rate|gyro", re.IGNORECASE)


@dataclass(frozen=True)
class ColumnChoice:
    """The user's naming of columns (None: recognised from the names and units)."""

    time: str | None = None
    angle: str | None = None
    rate: str | None = None
    xy: str | None = None
    pivot: tuple[float, float] | None = None
    deg: bool = False

    @property
    def given(self) -> bool:
        return any(v is not None for v in (self.time, self.angle, self.rate, self.xy, self.pivot)) or self.deg


@dataclass(frozen=True)
class Reading:
    """The columns chosen: time's, and the reading's kind ("angle", "rate", "rates": several axes of one
    gyro, "xy": a position) with its columns; named: given by the user."""

    time: int
    kind: str
    columns: tuple[int, ...]
    named: bool = False


def find_column(log: Log, spec: str, option: str, among: list[int]) -> int:
    """The column ``spec`` names: a number from 1, or a label or quantity name (case-insensitive)."""
    s = spec.strip()
    if s.isdigit():
        i = int(s) - 1
        if 0 <= i < len(log.columns):
            return i
        raise InputFileError(f"{log.source}: {option} {spec}: the file has {len(log.columns)} columns")
    for key in (lambda c: c.label, lambda c: c.name):
        hits = [i for i in among if key(log.columns[i]).lower() == s.lower()]
        if hits:
            return hits[0]
    raise InputFileError(f"{log.source}: {option} {spec!r} names no column; its columns are "
                         + ", ".join(f"{i + 1}: {log.columns[i].label!r}" for i in among))


def _time_column(log: Log, among: list[int], choice: ColumnChoice) -> int:
    if choice.time is not None:
        return find_column(log, choice.time, "--time-col", among)
    for i in among:
        c = log.columns[i]
        if _TIME.match(c.name) or c.unit in ("s", "ms"):
            return i
    raise InputFileError(_no_header(log) if not log.has_header else
                         f"{log.source}: no time column among {', '.join(repr(log.columns[i].label) for i in among)}; "
                         "expected one named t or Time (s), or name it with --time-col")


def _no_header(log: Log) -> str:
    return (f"{log.source}: the file has no header (its first row is data: {len(log.columns)} columns of numbers); "
            "name the columns by number, e.g. --time-col 1 --rate-col 2 (rad/s) or --angle-col 2 (rad), "
            "--deg for degrees")


def is_rate(c: Column) -> bool:
    return c.unit.lower() in RATE_UNITS or bool(_RATE.search(c.name))


def is_angle(c: Column) -> bool:
    return c.unit.lower() in ANGLE_UNITS or bool(_ANGLE.search(c.name))


def _axis_columns(log: Log, among: list[int], axis: str) -> list[int]:
    """The columns named as the ``axis`` (x, y or z) coordinate of a position (not its velocity)."""
    return [i for i in among if (m := _POSITION.match(log.columns[i].name)) and m.group(2).lower() == axis
            and not _NOT_POSITION.search(log.columns[i].name) and log.columns[i].unit.lower() not in RATE_UNITS]


def _is_acceleration(c: Column) -> bool:
    return bool(_ACCEL.search(c.name)) or c.unit in ACCELERATION_UNITS


def _accelerometer(log: Log, cols: list[int], what: str) -> str:
    return (f"{log.source}: an accelerometer ({', '.join(log.columns[i].label for i in cols)}) {what}: on a swinging "
            "body an accelerometer reads the swing's own accelerations (centripetal and tangential) besides gravity, "
            "so its tilt is not the swing angle; record the gyroscope's rate (phyphox: Gyroscope rotation rate), a "
            "video track or an angle sensor")


def _auto(log: Log, t: int, among: list[int]) -> Reading:
    rest = [i for i in among if i != t and not _NORM.search(log.columns[i].name)]
    rates = [i for i in rest if is_rate(log.columns[i]) and not _ACCEL.search(log.columns[i].name)]
    angles = [i for i in rest if is_angle(log.columns[i]) and i not in rates]
    if len(angles) == 1:
        return Reading(t, "angle", tuple(angles))
    if angles:
        raise InputFileError(f"{log.source}: several angle columns ({', '.join(log.columns[i].label for i in angles)}); "
                             "name one with --angle-col")
    if rates:
        return Reading(t, "rate" if len(rates) == 1 else "rates", tuple(rates))
    xs, ys, zs = (_axis_columns(log, rest, a) for a in "xyz")
    if xs and ys and zs:
        raise InputFileError(
            f"{log.source}: columns {log.columns[xs[0]].label!r}, {log.columns[ys[0]].label!r}, "
            f"{log.columns[zs[0]].label!r} without a unit that says what they read: a three-axis sensor's (an "
            "accelerometer's tilt is not the swing angle) or a point's position? name them: --rate-col for a "
            "gyro's axis, --xy X,Y for a tracked point")
    if len(xs) > 1 or len(ys) > 1:
        raise InputFileError(f"{log.source}: several positions ({', '.join(repr(log.columns[i].label) for i in xs + ys)}); "
                             "name the tracked point's with --xy X,Y (or --xy NAME for x_{NAME}, y_{NAME})")
    if xs and ys:
        return Reading(t, "xy", (xs[0], ys[0]))
    accel = [i for i in rest if _is_acceleration(log.columns[i])]
    if accel:
        raise InputFileError(_accelerometer(log, accel, "and no angle or rate"))
    if not log.has_header:
        raise InputFileError(_no_header(log))
    raise InputFileError(f"{log.source}: no angle, rate or x/y position column among "
                         f"{', '.join(repr(log.columns[i].label) for i in rest)}; name one with --angle-col, "
                         "--rate-col or --xy")


def choose(log: Log, among: list[int], choice: ColumnChoice) -> Reading:
    """The time and reading columns of the columns ``among`` (one data set or run of ``log``)."""
    t = _time_column(log, among, choice)
    for spec, kind, option in ((choice.angle, "angle", "--angle-col"), (choice.rate, "rate", "--rate-col")):
        if spec is not None:
            i = find_column(log, spec, option, among)
            if _is_acceleration(log.columns[i]):
                raise InputFileError(_accelerometer(log, [i], f"named as the {kind}"))
            return Reading(t, kind, (i,), True)
    if choice.xy is not None:
        parts = choice.xy.split(",")
        if len(parts) == 1:  # a track by its name, its columns named x_{NAME}, y_{NAME} (Tracker's subscripts)
            parts = [f"{a}_{{{choice.xy.strip()}}}" for a in "xy"]
        if len(parts) != 2:
            raise InputFileError(f"--xy {choice.xy!r}: expected two columns X,Y (labels or numbers) or a track's name")
        return Reading(t, "xy", tuple(find_column(log, p, "--xy", among) for p in parts), True)
    return _auto(log, t, among)


def degrees(log: Log, i: int, deg: bool) -> bool:
    """Whether column ``i`` is in degrees (its unit, or --deg for a column without one)."""
    unit = log.columns[i].unit.lower()
    return deg or unit.startswith(("°", "deg"))
