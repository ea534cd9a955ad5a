"""The swing's period as people measure it, and g where the rig gives the pendulum's length.

moi reports ω_n, the small-swing limit; a stopwatch, phyphox or Tracker gives the period of the swing as
it was, at its amplitude (on a compound rig longer than 2π/ω_n by about A²/16: 2K(sin(A/2))/π exactly; on a
wire suspension by its geometry's law, ``restoring.amplitude_factor``)
and damped (by 1/√(1 − ζ²)). Beside ω_n the result gives: the small-swing period 2π/ω_n, the period
at the record's largest amplitude by the fitted laws, and the period counted as a user counts it, from
the fitted swing's zero crossings over the record (its mean over the amplitudes the record went through).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from .restoring import amplitude_factor
from .wire import read_number


@dataclass(frozen=True)
class Periods:
    """Periods in s, each with its standard uncertainty from ω_n's combined u (relative, as ω_n's).

    small_swing: 2π/ω_n. amplitude: the record's largest swing, rad; at_amplitude: the damped period
    there by the fitted laws; counted: the fitted swing's mean period over the record from its zero
    crossings (None: fewer than three). g, g_u: ω_n²·L with the rig's length L, m/s² (None: no length).
    """

    small_swing: float
    small_swing_u: float
    amplitude: float
    at_amplitude: float
    at_amplitude_u: float
    counted: float | None
    counted_u: float | None
    g: float | None = None
    g_u: float | None = None

    def to_dict(self) -> dict[str, Any]:
        def num(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else float(v)

        return {k: num(getattr(self, k)) for k in ("small_swing", "small_swing_u", "amplitude", "at_amplitude",
                                                    "at_amplitude_u", "counted", "counted_u", "g", "g_u")}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Periods:
        def opt(key: str) -> float | None:
            return None if d[key] is None else read_number(d[key])

        return cls(read_number(d["small_swing"]), read_number(d["small_swing_u"]), read_number(d["amplitude"]),
                   read_number(d["at_amplitude"]), read_number(d["at_amplitude_u"]), opt("counted"),
                   opt("counted_u"), opt("g"), opt("g_u"))

    def lines(self) -> list[str]:
        """The report's lines."""
        out = [f"    period       = {self.small_swing:.6g} ± {self.small_swing_u:.2g} s small-swing (2π/ω_n); "
               f"{self.at_amplitude:.6g} ± {self.at_amplitude_u:.2g} s at the record's largest swing "
               f"{self.amplitude:.3g} rad"]
        if self.counted is not None:
            out.append(f"    period counted = {self.counted:.6g} ± {self.counted_u:.2g} s (the fitted swing's zero "
                       "crossings over the record: compare a period counted the same way)")
        if self.g is not None:
            out.append(f"    g            = {self.g:.6g} ± {self.g_u:.2g} m/s² (ω_n²·L, L the rig's length)")
        return out


def counted_period(t: np.ndarray, swing: np.ndarray) -> float | None:
    """The mean period of ``swing`` (an angle about its zero, or a rate) from its zero crossings, s: the
    crossings of the swing while it stands above a tenth of its largest (the decayed tail and a drifting
    zero do not count, as they would not for a user counting swings)."""
    from .signal import find_swings

    s = np.asarray(swing, dtype=float)
    crossings = find_swings(t, s, centre=0.0, hysteresis=0.1 * float(np.max(np.abs(s)))).crossings
    if crossings.size < 3:
        return None
    return float(2.0 * (crossings[-1] - crossings[0]) / (crossings.size - 1))


def periods(kind: str, omega_n: float, omega_n_u: float, omega_at: float, amplitude: float, zeta: float,
            t: np.ndarray, swing: np.ndarray, length: float | None = None,
            length_std: float | None = None, geometry: tuple[float, ...] = ()) -> Periods:
    """The periods of a fitted swing: omega_at the linear laws' ω at ``amplitude`` (ω_n without such a law),
    zeta the damping ratio, (t, swing) the fitted swing over the record, geometry a wire suspension's (e, b)."""
    rel = omega_n_u / omega_n if omega_n > 0 else math.nan
    small = 2.0 * math.pi / omega_n
    damped = 1.0 / math.sqrt(max(1.0 - min(zeta, 0.99) ** 2, 1e-6))
    at = 2.0 * math.pi / omega_at * amplitude_factor(kind, amplitude, omega_n, geometry) * damped
    counted = counted_period(t, swing)
    g = g_u = None
    if length is not None:
        g = omega_n**2 * length
        g_u = g * math.hypot(2 * rel, (length_std or 0.0) / length)
    return Periods(small, small * rel, amplitude, at, at * rel, counted, None if counted is None else counted * rel,
                   g, g_u)
