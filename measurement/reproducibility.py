"""Reproducibility between releases: what one record cannot see.

A release's fit knows its own noise; it cannot know what changes from one release to the next
(remounting the part, the pivot settling, a hand-held sensor). That scatter is estimated from
repeat releases: groups of releases of one object (a check standard measured again and again, a
part released several times), each group's own standard deviation pooled over the groups as
ISO 5725-2:2019 ("Accuracy (trueness and precision) of measurement methods and results — Part 2:
Basic method for the determination of repeatability and reproducibility of a standard measurement
method", its repeatability variance) pools the cells of one level:

    s² = Σ (n_i − 1)·s_i² / Σ (n_i − 1),   ν = Σ (n_i − 1)

Objects of different size are pooled on the relative deviations from each group's own mean, so a
rig's history of check standards and parts of any inertia gives one relative figure. It is stated
for ω_n: J = C/ω² carries twice its relative value.

One release's u counts, in this order (``for_release``): the rig's history (``pooled`` over the
appliance's store, source "history") where it pools at least ``MIN_DOF`` degrees of freedom; else the
figure its calibration keeps (``moi calibrate`` pools the references released more than once, source
"rig", Type A with its ν); else ``DEFAULT``, the documented Type B figure (source "default"), counted
too (GUM 4.3: a component known to exist and not measured gets a documented estimate; a measured
figure replaces it). ``docs/uncertainty.md`` gives the reasons and the benches' figures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

from .errors import InvalidInput

#: sources of a reproducibility figure
HISTORY, RIG, DEFAULT_SOURCE = "history", "rig", "default"

#: a group needs this many releases to say anything about the scatter between them
MIN_GROUP = 2

#: the fewest degrees of freedom a history needs before it enters one release's u (3 releases of one object, or
#: two objects released twice): a Type A line of ν = 1 that sets u would set k near 13 (Welch–Satterthwaite)
MIN_DOF = 2


class ReproducibilityError(InvalidInput):
    """Repeat releases that cannot be pooled (a group value that is not a positive finite number)."""


@dataclass(frozen=True)
class Reproducibility:
    """The between-release scatter of ω_n, relative (1σ), with its degrees of freedom.

    relative: 1σ of ω_n between releases over ω_n (None: not known); dof: its degrees of freedom (∞ for
    a Type B figure); groups, releases: what was pooled (0 for a stated figure); source: "history" (pooled
    from repeat releases), "rig" (stated in the rig file) or "default" (the documented Type B figure);
    counted: whether the budget's u holds it (every figure ``for_release`` gives is counted).
    """

    relative: float | None
    dof: float
    groups: int
    releases: int
    source: str
    counted: bool

    @property
    def known(self) -> bool:
        return self.relative is not None and self.source != DEFAULT_SOURCE

    def note(self) -> str:
        """What the budget's line says of its source."""
        if self.source == DEFAULT_SOURCE:
            rel = 100 * (self.relative or 0.0)
            return (f"one release, the rig's reproducibility not known: the documented default ±{rel:.2g} % of ω_n "
                    f"(±{2 * rel:.2g} % of J, Type B) is in u; measure ≥ 3 releases or calibrate with each reference "
                    "released twice to replace it: docs/uncertainty.md")
        if self.relative is None:
            return "not known: no group of repeat releases in the history"
        if self.source == RIG:
            refs = "1 reference" if self.groups == 1 else f"{self.groups} references"
            return f"rig: its calibration's {self.releases} releases of {refs} pooled (ISO 5725-2)"
        objects = "1 object" if self.groups == 1 else f"{self.groups} objects"
        return f"{self.source}: {self.releases} releases of {objects} pooled (ISO 5725-2)"

    def to_dict(self) -> dict[str, Any]:
        return {"relative": self.relative, "dof": self.dof if math.isfinite(self.dof) else None,
                "groups": self.groups, "releases": self.releases, "source": self.source, "counted": self.counted}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Reproducibility:
        return cls(d["relative"], math.inf if d["dof"] is None else float(d["dof"]), int(d["groups"]),
                   int(d["releases"]), d["source"], bool(d["counted"]))


#: The documented default (Type B, ν = ∞) for one release without a history: 0.1 % of ω_n (0.2 % of J).
#: Its source: the range (max − min)/mean of ω_n that a plain damped sinusoid shows between the releases of
#: the real torsion-rod records of docs/measured-data.md (a bicycle rod 0.204 % over 5 releases, a front
#: wheel on the rod 0.245 % over 3; hand-built rigs), as a standard deviation range/d₂ (d₂ = 2.326 and
#: 1.693: 0.088 % and 0.145 %), rounded: the scatter a record's own fit cannot see. Counted in one release's
#: u when neither a history nor the rig's calibration measured it; taken at its value (ν = ∞, GUM G.4.3: its own
#: uncertainty is not modelled, so it does not raise k) — a rig that scatters otherwise says so by measuring.
DEFAULT = Reproducibility(0.001, math.inf, 0, 0, DEFAULT_SOURCE, True)


def _group(values: Sequence[float]) -> list[float]:
    out = [float(v) for v in values]
    for v in out:
        if isinstance(v, bool) or not math.isfinite(v) or v <= 0:
            raise ReproducibilityError(f"a repeat release's value must be a positive number (ω_n or J), got {v!r}")
    return out


def pooled(groups: Iterable[Sequence[float]], *, power: float = 1.0) -> Reproducibility:
    """The pooled relative within-group standard deviation of repeat releases (ISO 5725-2).

    groups: the values of each object's releases (ω_n in rad/s, or J in kg·m² with ``power`` = −2,
    J = C/ω²: a relative deviation of J is −2 times ω_n's). A group of fewer than ``MIN_GROUP`` releases
    adds nothing. Returns relative None (source "history", 0 degrees of freedom) when no group has two.
    """
    ss = 0.0
    dof = 0
    n_groups = n_releases = 0
    for values in groups:
        g = _group(values)
        if len(g) < MIN_GROUP:
            continue
        mean = sum(g) / len(g)
        ss += sum((v / mean - 1.0) ** 2 for v in g)
        dof += len(g) - 1
        n_groups += 1
        n_releases += len(g)
    if dof == 0:
        return Reproducibility(None, 0.0, 0, 0, HISTORY, False)
    return Reproducibility(math.sqrt(ss / dof) / abs(power), float(dof), n_groups, n_releases, HISTORY, True)


def calibrated(relative: float, dof: float, groups: int = 0, releases: int = 0) -> Reproducibility:
    """The figure a rig's calibration keeps (source "rig"): its references' releases pooled, Type A with ν."""
    return Reproducibility(relative, dof, groups, releases, RIG, True)


def for_release(history: Reproducibility | None, rig: Reproducibility | None = None) -> Reproducibility:
    """What one release's u counts of the scatter between releases: its rig's ``history`` (``pooled``) where that
    pools at least ``MIN_DOF`` degrees of freedom, else the ``rig``'s calibration figure (``calibrated``) where it
    does, else the documented ``DEFAULT`` (Type B)."""
    for figure in (history, rig):
        if figure is not None and figure.known and figure.dof >= MIN_DOF:
            return figure
    return DEFAULT
