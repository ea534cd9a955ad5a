"""The identification's settings: plain values, no numerics imported (the configuration reads them)."""

from __future__ import annotations

from dataclasses import dataclass

from ..reproducibility import Reproducibility


@dataclass(frozen=True)
class Options:
    """Identification settings.

    discover: run the discovery loop (False: fit the declared model only).
    candidates: effects the loop may add (None: every library effect that
    exists on the rig).
    min_swings: fewer full swings in the record is an input error.
    bic_margin: an added effect must lower BIC (under the noise model) by
    more than this: e^(−margin/2) is the Bayes factor it must beat.
    outlier_sigma: residuals beyond this many robust σ are glitches.
    robust_scale: the soft-L1 loss's scale in robust σ of the declared
    model's residual (used only when wild samples are left after the screen).
    gap_periods: a gap of more than this many swing periods without samples
    ends the window, unless the swing clearly continues after it.
    rival_laws: restoring laws that the releases of one object withdrew together
    (``measurement.object_laws``): (law, the release's ω_n with it in rad/s, that
    model's effects, why in words); each is neither offered nor kept, and its
    ω_n is a rival carried whole into ω_n's uncertainty.
    focused: read the headline ω_n from the declared model where its ω_n is the more accurate
    (``identification.focus``; False: always from the discovered model).
    reproducibility: the rig's scatter of ω_n between releases (``measurement.reproducibility.pooled``
    over its history): a line of the budget, in u. None: the figure the rig's calibration keeps, else the
    documented default (``measurement.reproducibility.for_release``), counted.
    reference_amplitude: on a torsion rig, the swing amplitude (rad) a fitted amplitude law reads ω at
    (``identification.measurand``), and reference_basis what it is ("calibration": the references' of a
    calibration; "releases": the releases' of one object, read together). None: the rig's calibration's
    (``[calibration] amplitude``), else the record's own.
    """

    discover: bool = True
    candidates: tuple[str, ...] | None = None
    min_swings: float = 3.0
    bic_margin: float = 10.0
    outlier_sigma: float = 6.0
    robust_scale: float = 3.0
    gap_periods: float = 1.5
    max_rounds: int = 5
    rival_laws: tuple[tuple[str, float, tuple[str, ...], str], ...] = ()
    focused: bool = True
    reproducibility: Reproducibility | None = None
    reference_amplitude: float | None = None
    reference_basis: str = "calibration"
