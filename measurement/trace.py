"""Traces of a swing: validation and the trace CSV format (parsing only, no file I/O).

A trace is what one sensor read: the angle (an encoder, a camera; column
``angle``, rad) or the angular rate (a gyro, an IMU's rate axis; column
``rate``, rad/s). A rate is fitted as a rate (the model's velocity), never
integrated first: integrating turns the gyro's zero into a ramp and its noise
into a random walk, which a fit would read as physics.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from .errors import TraceError

#: the smallest time step a trace may have, s (the trace CSV writes t with 1 ns resolution)
MIN_STEP = 1e-9
#: bounds of a plausible trace: Unix times fit, a swing's angle is a few rad
MAX_ABS_TIME = 1e10
MAX_ABS_ANGLE = 1e3
#: what a trace's sensor reads: its column name, also its ``quantity``
READINGS = ("angle", "rate")
#: the SI unit of each reading
READING_UNITS = {"angle": "rad", "rate": "rad/s"}


@dataclass(frozen=True, eq=False)
class Trace:
    """A recorded swing: times t (s, strictly increasing, possibly uneven) and the sensor's reading.

    angle: the reading, one per time: the angle (rad), or with quantity "rate" the angular
    rate (rad/s) as a gyro gives it, its zero and drift left in (the fit takes them).
    flags: facts about the acquisition the identification must report
    (e.g. "dropped_frames"); meta: free-form provenance (source, sensor).
    """

    t: np.ndarray
    angle: np.ndarray
    source: str = "trace"
    flags: tuple[str, ...] = ()
    meta: dict = field(default_factory=dict)
    quantity: str = "angle"

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        a = np.asarray(self.angle, dtype=float)
        if t.ndim != 1 or a.ndim != 1 or t.shape != a.shape:
            raise TraceError(f"{self.source}: t and angle must be 1-D columns of equal length, got {t.shape} and {a.shape}")
        if self.quantity not in READINGS:
            raise TraceError(f"{self.source}: a trace reads {self.quantity!r}; expected one of {', '.join(READINGS)}")
        if t.size == 0:
            raise TraceError(f"{self.source}: the trace is empty; expected rows of t (s) and angle (rad)")
        bad = ~np.isfinite(t) | ~np.isfinite(a)
        if bad.any():
            i = int(np.argmax(bad))
            raise TraceError(
                f"{self.source}: non-finite value (NaN/inf gap) at row {i + 1} (t={t[i]!r}); "
                "expected finite numbers in every row (drop the gap rows: timestamps may be uneven)"
            )
        dt = np.diff(t)
        if (dt <= 0).any():
            i = int(np.argmax(dt <= 0))
            raise TraceError(
                f"{self.source}: time is not strictly increasing at row {i + 2} "
                f"(t={t[i + 1]!r} after {t[i]!r}); expected increasing timestamps in s"
            )
        if (dt < MIN_STEP).any():
            i = int(np.argmax(dt < MIN_STEP))
            raise TraceError(
                f"{self.source}: samples {float(dt[i])!r} s apart at row {i + 2}; expected timestamps in s "
                f"at least {MIN_STEP:g} s apart (the trace CSV's resolution)"
            )
        big_t, big_a = float(np.max(np.abs(t))), float(np.max(np.abs(a)))
        if big_t > MAX_ABS_TIME or big_a > MAX_ABS_ANGLE:
            raise TraceError(
                f"{self.source}: |t| up to {big_t:.3g} s and |angle| up to {big_a:.3g} rad; expected |t| <= "
                f"{MAX_ABS_TIME:g} s and |{self.quantity}| <= {MAX_ABS_ANGLE:g} {READING_UNITS[self.quantity]} "
                "(in rad, not counts or degrees)"
            )
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "angle", a)

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def duration(self) -> float:
        """s"""
        return float(self.t[-1] - self.t[0])

    @property
    def sample_rate(self) -> float:
        """Median sample rate, Hz."""
        return float(1.0 / np.median(np.diff(self.t))) if len(self) > 1 else float("nan")

    def to_csv(self, header_comment: str | None = None) -> str:
        """CSV text with columns t (s) and angle (rad) (or rate, rad/s); comment lines start with '#'."""
        buf = io.StringIO()
        if header_comment:
            for line in header_comment.splitlines():
                buf.write(f"# {line}\n")
        buf.write(f"t,{self.quantity}\n")
        for ti, ai in zip(self.t, self.angle):
            buf.write(f"{ti:.9f},{ai:.12g}\n")
        return buf.getvalue()


def csv_content(lines: Iterable[str]) -> list[tuple[int, str]]:
    """(line number from 1, line) of a CSV's header and rows: blank lines and '#' comments left out."""
    return [(n, line) for n, line in enumerate(lines, start=1) if line.strip() and not line.lstrip().startswith("#")]


def csv_header(content: list[tuple[int, str]]) -> list[str]:
    """The column names of ``csv_content``'s first line (stripped; [] when there is none)."""
    try:
        return [h.strip() for h in next(csv.reader([content[0][1]]))] if content else []
    except csv.Error:  # a cell beyond the csv module's field limit: no header this parser knows
        return []


def parse_trace_csv(lines: Iterable[str], source: str = "trace") -> Trace:
    """Parse a trace CSV: a header row with columns t (s) and angle (rad), or t and rate (rad/s, a gyro).

    A trace with an angle column is an angle trace whatever else it holds; other
    columns are ignored, lines starting with '#' are comments.
    Raises TraceError naming the row and what was expected.
    """
    content = csv_content(lines)
    if not content:
        raise TraceError(f"{source}: no header row; expected a CSV with columns t (s) and angle (rad)")
    header = csv_header(content)
    quantity = "rate" if "rate" in header and "angle" not in header else "angle"
    missing = [c for c in ("t", quantity) if c not in header]
    if missing:
        raise TraceError(f"{source}: missing column(s) {', '.join(missing)} in header {header}; expected columns t (s) "
                         "and angle (rad), or t and rate (rad/s)")
    it, ia = header.index("t"), header.index(quantity)
    t, a = [], []
    for n, line in content[1:]:
        try:
            row = next(csv.reader([line]))
        except csv.Error as exc:  # e.g. a cell longer than the csv module's field limit (131,072 characters)
            raise TraceError(f"{source}: line {n}: {exc}; expected numbers for t (s) and angle (rad)") from None
        if len(row) <= max(it, ia):
            raise TraceError(f"{source}: line {n} has {len(row)} cells; expected at least {max(it, ia) + 1} (t and angle)")
        try:
            t.append(float(row[it]))
            a.append(float(row[ia]))
        except ValueError:
            raise TraceError(f"{source}: line {n}: non-numeric cell in {row!r:.200}; expected numbers for t (s) and angle (rad)") from None
    if not t:
        raise TraceError(f"{source}: the trace is empty (a header but no data rows)")
    for n_value, (tv, av) in enumerate(zip(t, a)):
        if not (math.isfinite(tv) and math.isfinite(av)):
            # find the file line of this data row for the message
            line_no = content[1 + n_value][0]
            raise TraceError(f"{source}: line {line_no}: NaN/inf in t or angle; expected finite numbers (drop gap rows instead)")
    return Trace(np.asarray(t), np.asarray(a), source=source, quantity=quantity)
