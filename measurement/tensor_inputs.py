"""What the inertia tensor's solve (``measurement.tensor``) takes of the measurements: each orientation's
inertia from its releases (``axis_reading``: pooled as a part's releases are for its verdict), and what every
orientation shares through the rig (``RigShared``: its stiffness calibration and tare, which go into the
set's covariance rather than into each orientation's own uncertainty). SI units, kg·m².
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .errors import TensorError
from .result import IdentificationResult, _jsonable, _num
from .rig import Rig
from .verdict import QualityRules, Reading, Specification, combine


@dataclass(frozen=True)
class AxisReading:
    """The part's inertia about one orientation's swing axis, from its releases (kg·m²).

    value: the part about the swing axis (tare removed when the rig has one).
    u: 1σ of what is this orientation's own (fit, repeatability, a record's own calibration).
    rig_inertia: J of the whole swinging rig (part + fixture), which the stiffness calibration scales.
    releases: how many; used: 0-based indices combined; excluded: {index, reason} of the others.
    invalid: why the orientation cannot be used (None: it can).
    """

    value: float | None
    u: float | None
    rig_inertia: float | None = None
    releases: int = 1
    used: tuple[int, ...] = (0,)
    excluded: tuple[dict[str, Any], ...] = ()
    invalid: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"value": _num(self.value), "u": _num(self.u), "releases": self.releases, "used": list(self.used),
                "excluded": _jsonable(list(self.excluded)), "invalid": self.invalid}


@dataclass(frozen=True)
class RigShared:
    """What every orientation of a set shares through the rig.

    scale_rel: relative 1σ of the restoring constant (J ∝ k: scales every J alike).
    tare, tare_std: the fixture's inertia and its 1σ, kg·m² (None: no tare, J is the part's).
    scale_tare_corr: the correlation of k and the tare (one calibration regression gives both).
    """

    scale_rel: float = 0.0
    tare: float | None = None
    tare_std: float = 0.0
    scale_tare_corr: float = 0.0

    def common_covariance(self, rig_J: np.ndarray) -> np.ndarray:
        """Covariance (kg·m²)² the orientations' J − tare share through k and the tare, each J_i = k/ω_i².

        cov_ij = s_i·s_j + σ_I0² − r·σ_I0·(s_i + s_j), s_i = scale_rel·J_i (J − I0: ∂/∂k = J/k, ∂/∂I0 = −1).
        """
        s = self.scale_rel * np.asarray(rig_J, dtype=float)
        t = self.tare_std
        return np.outer(s, s) + t**2 - self.scale_tare_corr * t * (s[:, None] + s[None, :])

    @property
    def quantity(self) -> str:
        """The result key that holds the part's inertia about the swing axis."""
        return "J" if self.tare is None else "J_object"

    @classmethod
    def of(cls, rig: Rig) -> "RigShared":
        """From the rig every orientation swings on; a rig that cannot serve a tensor set is refused."""
        if rig.kind != "torsion":
            raise TensorError("a tensor set swings on a torsion rig: a compound rig's m·g·S changes with every "
                              "mounting of the part")
        if rig.object is not None:
            raise TensorError("the rig has an [object] transfer, but a tensor plan moves each orientation to the "
                              "centre of mass itself (offset = [x, y, z]); drop [object] from the rig")
        k, k_std = rig.restoring_constant, rig.restoring_constant_std
        scale = (k_std or 0.0) / k if k else 0.0
        corr = 0.0
        if rig.stiffness_tare_covariance and k_std and rig.tare_inertia_std:
            corr = rig.stiffness_tare_covariance / (k_std * rig.tare_inertia_std)
        return cls(scale, rig.tare_inertia, rig.tare_inertia_std or 0.0, corr)


def _release_reading(result: IdentificationResult, shared: RigShared) -> Reading:
    """One release as the part verdict reads it, its systematic part made of what is this record's own
    and what the set shares (the shared part goes into the set's covariance instead)."""
    reading = Reading.from_result(result, shared.quantity)
    if reading.value is None or reading.u_random is None:
        return reading
    u_total = result.uncertainty_budget[shared.quantity].u  # a value read with u_random has its budget
    common = math.sqrt(max(float(shared.common_covariance(np.array([float(result.J or 0.0)]))[0, 0]), 0.0))
    own_systematic = math.sqrt(max(u_total**2 - reading.u_random**2 - common**2, 0.0))
    return Reading(reading.value, reading.u_random, own_systematic, reading.flags, reading.swings)


def axis_reading(results: Sequence[IdentificationResult], shared: RigShared,
                 rules: QualityRules = QualityRules()) -> AxisReading:
    """One orientation's inertia from its releases' results.

    The releases are pooled as the part verdict pools a part's releases (``verdict.combine``: INVALID
    releases and one that disagrees with the others excluded with their reasons; the mean, its
    uncertainty the larger of Type A and the propagated fit uncertainties).
    """
    if not results:
        return AxisReading(None, None, None, 0, (), (), "no releases")
    readings = [_release_reading(r, shared) for r in results]
    # no specification applies to one axis of a tensor: the pooling alone is wanted, so the zone is all numbers
    anything = Specification(shared.quantity, 0.0, -1e300, 1e300, rule="simple")
    pooled = combine(readings, anything, rules)
    if pooled.verdict == "INVALID" or pooled.mean is None:
        reasons = "; ".join(pooled.decision.reasons) or "no usable release"
        return AxisReading(None, None, None, len(results), pooled.used, pooled.excluded, reasons)
    u_random = max(pooled.u_typeA or 0.0, pooled.u_fit or 0.0)
    own = max(readings[i].u_systematic for i in pooled.used)
    rig_J = [float(j) for i in pooled.used if (j := results[i].J) is not None]
    rig_inertia = float(np.mean(rig_J)) if len(rig_J) == len(pooled.used) else None  # only when every release has it
    return AxisReading(pooled.mean, math.hypot(u_random, own), rig_inertia, len(results), pooled.used, pooled.excluded)


