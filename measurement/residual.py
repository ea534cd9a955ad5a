"""What a residual says, as a result carries it: the diagnostics of one fit, and their words.

Plain data (numbers and sentences, no numerics imported): ``measurement.diagnostics`` computes them
from a fit (``diagnose``); the result JSON's ``diagnostics`` is ``as_dict`` and ``from_dict`` reads it
back (a value the JSON cannot hold, NaN or ±∞, is written null and read back NaN).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Mapping

from .wire import read_number

#: the key prefix of each envelope law's error in ``as_dict``
_ENVELOPE = "envelope_error_"

#: residual RMS / noise floor below which the model is "at the noise floor" (reported, decides nothing)
AT_NOISE = 1.10
#: BIC gain (under the noise model) above which the residual holds structure
STRUCTURE_MARGIN = 10.0
#: residual RMS over the noise floor from which a named shape in it is worth a flag
NAMED_ABOVE_NOISE = 1.5


@dataclass(frozen=True)
class Diagnostics:
    """Residual diagnostics of one fit. Angles in rad, frequencies in Hz."""

    residual_rms: float
    noise_floor: float
    rms_ratio: float
    lag1: float
    whiteness_p: float
    white: bool
    swing_hz: float
    line_hz: float | None
    line_fraction: float
    low_frequency_fraction: float
    envelope_law: str | None
    envelope_errors: dict
    stopped: bool
    freq_amp_slope: float
    freq_amp_t: float
    centre_slope: float
    centre_t: float
    asymmetry: float
    asymmetry_t: float
    #: amplitude lost per full swing, ΔA = d0 + d1·A + d2·A² (rad), with t-values:
    #: d0 is dry friction's signature, d1 linear damping's, d2 air drag's
    decrement: tuple[float, float, float] = (0.0, 0.0, 0.0)
    decrement_t: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: BIC change when the residual is regressed on the shapes an unmodelled
    #: effect leaves (``structure_test``), under the noise model; < −margin: structure
    structure_bic: float = 0.0
    #: BIC change when the residual is regressed on the envelope shapes θ·τ, θ·τ² alone
    envelope_bic: float = 0.0

    @property
    def at_noise_floor(self) -> bool:
        return self.rms_ratio <= AT_NOISE

    @property
    def structured(self) -> bool:
        """The residual holds deterministic structure beyond its noise model: something is unmodelled."""
        return self.structure_bic < -STRUCTURE_MARGIN

    def named_structure(self, unit: str = "rad") -> list[str]:
        """The shapes in the residual that can be named, each large enough to matter, in words.

        An envelope that decays otherwise than the model's (a damping law
        it lacks); a spectral line away from the swing frequency (another
        mode, a vibration), a trend slower than the swing, unequal
        half-swings: each of these must hold a fair share of a residual
        that stands clear of the noise (a line at the swing frequency is the
        model's own phase error, judged by what it does to ω_n instead).
        """
        out: list[str] = []
        # the envelope test carries its own margin (it is a BIC under the noise model, two shapes):
        # a damping law the model lacks shows there even close to the noise
        if self.envelope_bic < -STRUCTURE_MARGIN:
            out.append(f"the swing decays otherwise than the model: its envelope departs from the model's "
                       f"(ΔBIC {self.envelope_bic:+.0f})")
        if self.rms_ratio < NAMED_ABOVE_NOISE:
            return out
        off_swing = (self.line_hz is not None and math.isfinite(self.swing_hz) and self.swing_hz > 0
                     and abs(self.line_hz / self.swing_hz - 1.0) > 0.15)
        if off_swing and self.line_fraction >= 0.3:
            out.append(f"a spectral line at {self.line_hz:.4g} Hz holds {100 * self.line_fraction:.0f} % of the residual power")
        if self.low_frequency_fraction >= 0.5:
            out.append(f"a trend slower than the swing holds {100 * self.low_frequency_fraction:.0f} % of the residual power")
        if abs(self.asymmetry_t) >= 6 and abs(self.asymmetry) >= 3 * self.noise_floor:
            out.append(f"the half-swings differ by {self.asymmetry:+.3g} {unit} (t = {self.asymmetry_t:.1f})")
        return out

    def as_dict(self) -> dict[str, Any]:
        """The flat table of the result JSON's ``diagnostics`` (read back by ``from_dict``)."""
        d = asdict(self)
        d.pop("envelope_errors")
        for key in ("decrement", "decrement_t"):
            for name, v in zip(("const", "linear", "quadratic"), d.pop(key)):
                d[f"{key}_{name}"] = v
        for law, err in self.envelope_errors.items():
            d[f"{_ENVELOPE}{law}"] = err
        d["structured"] = self.structured
        d["at_noise_floor"] = self.at_noise_floor
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Diagnostics:
        """Read back ``as_dict`` (the result JSON's ``diagnostics``): the decrement's and the envelope laws'
        keys gathered again, ``structured`` and ``at_noise_floor`` left to the properties that compute them."""
        kw: dict[str, Any] = {}
        for f in fields(cls):
            if f.name in ("decrement", "decrement_t"):
                kw[f.name] = tuple(read_number(d[f"{f.name}_{name}"]) for name in ("const", "linear", "quadratic"))
            elif f.name == "envelope_errors":
                # a law's error is ∞ where the law does not apply (1/A crossing zero), written null
                kw[f.name] = {k.removeprefix(_ENVELOPE): math.inf if v is None else v
                              for k, v in d.items() if k.startswith(_ENVELOPE)}
            elif f.name in d:
                # null is a number that was not finite, except where None is a value (no line, no law)
                kw[f.name] = d[f.name] if "None" in str(f.type) else read_number(d[f.name])
        return cls(**kw)

    def describe(self, unit: str = "rad") -> list[str]:
        """Plain sentences on the residual's size and shape; unit: the reading's (rad, or rad/s for a gyro)."""
        out = [f"RMS {self.residual_rms:.3g} {unit} = {self.rms_ratio:.3g} × the noise floor ({self.noise_floor:.3g} {unit}, estimated from the data)"]
        if self.white:
            out.append(f"white (lag-1 autocorrelation {self.lag1:+.2f}, Ljung–Box p = {self.whiteness_p:.2g})")
        else:
            out.append(f"not white: lag-1 autocorrelation {self.lag1:+.2f} (Ljung–Box p = {self.whiteness_p:.2g})")
        if self.line_hz is not None and self.line_fraction >= 0.2:
            ratio = self.line_hz / self.swing_hz if self.swing_hz > 0 else float("nan")
            out.append(f"spectral line at {self.line_hz:.4g} Hz ({ratio:.3g} × the swing frequency {self.swing_hz:.4g} Hz)"
                       f" holds {100 * self.line_fraction:.0f} % of the residual power")
        if self.low_frequency_fraction >= 0.3:
            out.append(f"{100 * self.low_frequency_fraction:.0f} % of the residual power is slower than the swing (trend or drift)")
        if abs(self.freq_amp_t) >= 4:
            out.append(f"frequency depends on amplitude beyond the model: dω/d(A²) = {self.freq_amp_slope:+.3g} rad/s per rad² (t = {self.freq_amp_t:.1f})")
        if abs(self.centre_t) >= 4:
            out.append(f"the swing centre moves by {self.centre_slope:+.3g} {unit}/s against the model (t = {self.centre_t:.1f})")
        if abs(self.asymmetry_t) >= 4:
            out.append(f"positive and negative half-swings differ by {self.asymmetry:+.3g} {unit} in amplitude (t = {self.asymmetry_t:.1f})")
        terms = [f"{name} part (t = {t:.1f})" for name, t in zip(("a constant", "a linear", "a quadratic"), self.decrement_t) if t >= 3]
        if terms:
            out.append("the amplitude lost per swing has " + ", ".join(terms) + " in the amplitude")
        if self.envelope_law:
            out.append(f"the measured envelope decays most like a{'n' if self.envelope_law[0] in 'aeiou' else ''} {self.envelope_law} law")
        if self.stopped:
            out.append("the pendulum came to rest within the record (stuck by friction)")
        return out
