"""Whether a Gauge R&R is the study the AIAG MSA manual's figures rest on (4th edition, ch. III: 10 parts that
span the process's range, 2–3 appraisers, 2–3 trials each), and what a reader must know when it is not. A
smaller study's %GRR and ndc are indicative; when its parts are all alike (the part-to-part variation PV about
0), %GRR of the process variation (GRR/TV, TV² = GRR² + PV²) goes to 100 % and ndc (⌊1.41·PV/GRR⌋) to 0
whatever the gauge: only %GRR of the tolerance then speaks of the gauge. The one rule the Gauge R&R page, its
PDF and the capability warnings (``gauge.capability_warnings``) follow."""

from __future__ import annotations

from typing import Protocol


class GaugeRR(Protocol):
    """What the rule reads of a ``gauge.GaugeRR`` (typed here so that ``gauge`` may use the rule)."""

    @property
    def parts(self) -> tuple[str, ...]: ...

    @property
    def appraisers(self) -> tuple[str, ...]: ...

    @property
    def pv(self) -> float: ...

    @property
    def tv(self) -> float: ...

    @property
    def trials(self) -> int: ...

    def pct_of_process(self, sigma: float) -> float: ...

#: the manual's design: parts, appraisers (fewest, most usual), trials (fewest, most usual)
DESIGN_PARTS, DESIGN_APPRAISERS, DESIGN_TRIALS = 10, (2, 3), (2, 3)
#: PV below this share of TV: the parts do not span the process
PV_SHARE_MIN = 0.1


def design(g: GaugeRR) -> str:
    """The study's size in words: "3 parts × 2 appraisers × 2 trials"."""
    p, a, r = len(g.parts), len(g.appraisers), g.trials
    return (f"{p} part{'s' if p != 1 else ''} × {a} appraiser{'s' if a != 1 else ''} × "
            f"{r} trial{'s' if r != 1 else ''}")


def below_design(g: GaugeRR) -> str | None:
    """Why ``g`` is smaller than the manual's design, in words (None: it is not)."""
    if len(g.parts) >= DESIGN_PARTS and len(g.appraisers) >= DESIGN_APPRAISERS[0] and g.trials >= DESIGN_TRIALS[0]:
        return None
    (a0, a1), (r0, r1) = DESIGN_APPRAISERS, DESIGN_TRIALS
    return (f"the study ({design(g)}) is far below the AIAG MSA design ({DESIGN_PARTS} parts spanning the "
            f"process's range, {a0}–{a1} appraisers, {r0}–{r1} trials): its figures are indicative")


def parts_alike(g: GaugeRR) -> bool:
    """The parts do not span the process: PV below ``PV_SHARE_MIN`` of TV."""
    return g.pv < PV_SHARE_MIN * g.tv


def adequate(g: GaugeRR) -> bool:
    """The manual's design, with parts that span the process: its figures are the gauge's."""
    return below_design(g) is None and not parts_alike(g)


def cautions(g: GaugeRR) -> tuple[str, ...]:
    """What a reader must know before the verdict (empty: nothing)."""
    short = below_design(g)
    out = [short] if short else []
    if parts_alike(g):
        out.append(f"the part-to-part variation PV is about 0 ({g.pct_of_process(g.pv):.1f} % of the total): the "
                   "parts do not span the process, so %GRR of the process variation and ndc are meaningless; "
                   "judge the gauge by %GRR of the tolerance")
    return tuple(out)
