"""What the identification's steps found on one record, read by the flags, the report's sentences and
the result's assembly (each its own module: the words apart from the fitting, as lmfit keeps its
report apart from its minimizer)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..fit import ModelFit
from ..model import Model
from ..reproducibility import DEFAULT as DEFAULT_REPRODUCIBILITY
from ..reproducibility import Reproducibility
from ..residual import Diagnostics
from ..result import DiscoveryStep, ModelForm, ReadAt, SegmentCheck
from ..rig import Rig
from ..trace import Trace
from .focus import DISCOVERED, Focus
from .preparation import Prepared
from .quantities import Inertias
from .rivals import LawRival, Withdrawn


@dataclass(frozen=True, eq=False)
class Findings:
    """One record identified. SI units.

    base: the declared model's fit on the final samples; final: the model reported; slipped_from:
    the final model before ``keep_nested_order`` (``beaten_by``: the model it contains that fitted
    better, or None); follows / follow_ratio: ``follows_swing`` of the final fit; view: the camera
    view measured on the record (``measurement.vision.marker_pair``) or None; omega_n_view: the
    1σ of ω_n it carries (rad/s); nominal: the sensor's fitted scale parameters and ω_n were they
    at their nominal 0 (``omega_n_at_nominal_scale``); nfev: the simulations spent; rival_laws: the
    restoring laws the releases of the object withdrew together (``Options.rival_laws``).
    """

    trace: Trace
    rig: Rig
    prep: Prepared
    declared: Model
    base: ModelFit
    final: ModelFit
    steps: tuple[DiscoveryStep, ...]
    withdrawn: Withdrawn | None
    law: LawRival | None
    segments: SegmentCheck | None
    form: ModelForm
    diag: Diagnostics
    n_outliers: int
    slipped_from: ModelFit
    beaten_by: ModelFit | None
    follows: bool
    follow_ratio: float
    view: dict[str, Any] | None
    omega_n_view: float | None
    inertias: Inertias
    nominal: tuple[list[str], float] | None
    nfev: int
    bic_margin: float
    rival_laws: tuple[tuple[str, float, tuple[str, ...], str], ...] = ()
    #: the model the headline ω_n is read from (``focus``); None: the final model
    focus: Focus | None = None
    #: the scatter between releases this record cannot see (``Options.reproducibility``, else the rig's
    #: calibration figure, else the documented default: ``reproducibility.for_release``)
    reproducibility: Reproducibility = DEFAULT_REPRODUCIBILITY
    #: the swing amplitude the headline ω_n is read at (``measurand``)
    read_at: ReadAt = ReadAt()

    @property
    def headline(self) -> Focus:
        """The model of the headline ω_n and J, and its model form."""
        return self.focus if self.focus is not None else Focus(self.final, self.form, DISCOVERED)

    @property
    def omega_n(self) -> float:
        return self.final.value("omega_n")

    @property
    def omega_n_std(self) -> float:
        return self.final.stdev("omega_n")

    @property
    def ambiguous(self) -> bool:
        """Rival models spread ω_n by more than the fit's σ."""
        return self.form.ambiguous(self.omega_n_std)
