"""A law is kept only where it is a property of the object: the releases of one object weigh it together.

A restoring law the discovery loop adds to one release (a cubic spring)
moves ω_n; one record alone may hold it for another reason (a slow line in
the sensor, a drifting zero, a clamp that settles), and then the law's
value is whatever that stand-in needed. A law of the object is the same in
every release: fitted to each, its value keeps one sign and a consistent
size (within ``SIZE_RATIO`` of each other where it is determined, beyond
``DETERMINED_SIGMA`` σ of zero). Where it does not, each release that kept
it is identified again without it: the point estimate is the simpler
model's, and the distance to the law's ω_n enters its uncertainty, named
(a rival model of weight 1, flag model_ambiguous when it exceeds the fit's σ).
Where it does, and every release determines it, it is the object's law in
every release: one that did not add it alone (its swing too small for the
loop to pay for it) is reported with the law fitted, so that every release
reads ω_n by the same law where it is read (its small-swing limit on a
compound rig; on a torsion rig at one reference amplitude,
``identification.measurand``), not some by the law and some at their own amplitude.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

from .effects import EFFECTS
from .errors import MeasurementError
from .identification.options import Options
from .identification.pipeline import identify
from .result import IdentificationResult
from .rig import Rig
from .trace import Trace

#: a law's value counts toward its sign and size where it is this many σ from zero
DETERMINED_SIGMA = 3.0
#: the largest ratio of a law's determined values between releases of one object ("a consistent size")
SIZE_RATIO = 3.0


@dataclass(frozen=True)
class LawAcross:
    """A restoring law's values over the releases of one object.

    law: the effect; parameter: the one judged (its first); values / stds: per release, fitted with
    the law (None where the release could not be fitted with it); kept_in: the releases whose own
    identification kept it; stable: one sign and a consistent size where determined; with_law: per
    release, its identification with the law declared where its own did not keep it (else None).
    """

    law: str
    parameter: str
    values: tuple[float | None, ...]
    stds: tuple[float | None, ...]
    kept_in: tuple[int, ...]
    with_law: tuple[IdentificationResult | None, ...] = ()

    @property
    def everywhere(self) -> bool:
        """Stable, and determined in every release: the object's law in each."""
        return self.stable and len(self.determined) == len(self.values) >= 2

    @property
    def determined(self) -> list[float]:
        return [v for v, s in zip(self.values, self.stds)
                if v is not None and s is not None and abs(v) >= DETERMINED_SIGMA * s]

    @property
    def stable(self) -> bool:
        d = self.determined
        if len(d) < 2:
            return True  # nothing across the releases contradicts it
        same_sign = all(v > 0 for v in d) or all(v < 0 for v in d)
        sizes = [abs(v) for v in d]
        return same_sign and max(sizes) <= SIZE_RATIO * min(sizes)

    def describe(self) -> str:
        vals = ", ".join("–" if v is None else f"{v:.3g} ± {s:.2g}" for v, s in zip(self.values, self.stds))
        verdict = ("one sign and a consistent size: a law of the object" if self.stable else
                   "not one sign and a consistent size: not a law of the object")
        return f"{self.law}.{self.parameter} fitted to each release: {vals} ({verdict})"


def restoring_laws() -> list[str]:
    """The library's restoring laws (role "stiffness"): the effects that move ω_n through the amplitude."""
    return [n for n, cls in EFFECTS.items() if cls.role == "stiffness"]


def law_across(law: str, results: Sequence[IdentificationResult], traces: Sequence[Trace], rig: Rig,
               options: Options) -> LawAcross:
    """``law`` fitted to every release: from its own result where it kept it, else its final model with the law
    declared (no discovery: the release's own effects and the law)."""
    parameter = EFFECTS[law].parameters[0].name
    values: list[float | None] = []
    stds: list[float | None] = []
    with_law: list[IdentificationResult | None] = []
    for r, tr in zip(results, traces):
        with_law.append(None)
        if law not in r.effects:
            try:
                r = identify(tr, rig.with_declared(tuple(r.effects) + (law,)), replace(options, discover=False))
            except MeasurementError:
                values.append(None)
                stds.append(None)
                continue
            with_law[-1] = r
        q = r.stiffness.get(law, {}).get(parameter)
        values.append(None if q is None else q.value)
        stds.append(None if q is None else q.std)
    kept = tuple(i for i, r in enumerate(results) if law in r.added_effects)
    return LawAcross(law, parameter, tuple(values), tuple(stds), kept, tuple(with_law))


def laws_of_the_object(results: list[IdentificationResult], traces: Sequence[Trace], rig: Rig,
                       options: Options) -> tuple[list[IdentificationResult], list[LawAcross]]:
    """The releases' results with every restoring law that is not a property of the object withdrawn.

    Returns (the results, the laws weighed across the releases). A release that kept an unstable
    law is identified again with that law neither offered nor kept, its ω_n with the law a rival
    carried whole into its uncertainty (``Options.rival_laws``).
    """
    weighed: list[LawAcross] = []
    for law in restoring_laws():
        if not any(law in r.added_effects for r in results) or len(results) < 2:
            continue
        across = law_across(law, results, traces, rig, options)
        weighed.append(across)
        note = across.describe()
        if across.everywhere:
            for i, r_law in enumerate(across.with_law):
                if r_law is not None:
                    results[i] = _with_the_objects_law(r_law, results[i], note)
            continue
        if across.stable:
            continue
        for i in across.kept_in:
            r = results[i]
            allowed = options.candidates if options.candidates is not None else tuple(EFFECTS)
            rival = (law, r.omega_n, tuple(r.effects), note)
            try:
                results[i] = identify(traces[i], rig, replace(
                    options, candidates=tuple(n for n in allowed if n != law),
                    rival_laws=tuple(options.rival_laws) + (rival,)))
            except MeasurementError:
                continue
    return results, weighed


def _with_the_objects_law(r_law: IdentificationResult, own: IdentificationResult, note: str) -> IdentificationResult:
    """A release's identification with the object's law declared, reported as the release's own with the
    law added by its sisters."""
    law = next(n for n in r_law.effects if n not in own.effects)
    return replace(r_law, declared_effects=own.declared_effects,
                   added_effects=tuple(n for n in r_law.effects if n not in own.declared_effects),
                   steps=own.steps, structure=r_law.structure + (
                       f"{law} was added from this object's other releases, which keep it: {note}; this release "
                       "alone did not pay for it, and without it its ω_n would read the swing's own amplitude, "
                       f"{own.omega_n:.6g} rad/s",))
